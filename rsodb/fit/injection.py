"""Synthetic passes from known truths, for injection-recovery tests and benchmarks.

`inject` renders a forward model at chosen parameter values on the times of a template pass,
adds a magnitude offset and Gaussian noise, and returns a new `Pass` that can be archived and
fitted like an observation. `window` cuts a pass to a time range first (e.g. the published
workflow's 30 s).
"""
from __future__ import annotations

import hashlib
from typing import Mapping

import numpy as np

from ingest.observation import ARRAY_FIELDS, Pass

__all__ = ["inject", "window"]


def window(observed: Pass, start_s: float, duration_s: float, stride: int = 1) -> Pass:
    """The samples of `observed` with ``start_s <= t_s <= start_s + duration_s``, every `stride`-th.

    Returns a plain `Pass` (an archived pass loses its archive identity).
    """
    t_s = observed.t_s
    index = np.flatnonzero((t_s >= start_s) & (t_s <= start_s + duration_s))[::stride]
    if index.size < 2:
        raise ValueError(f"window start_s={start_s}, duration_s={duration_s} holds {index.size} samples of a "
                         f"{observed.duration_s:.1f} s pass; choose a window inside the pass")
    arrays = {name: getattr(observed, name)[index] for name in ARRAY_FIELDS}
    corrected = None if observed.mag_corrected is None else observed.mag_corrected[index]
    return Pass(**{**_scalar_fields(observed), **arrays, "mag_corrected": corrected})


def _scalar_fields(observed: Pass) -> dict:
    names = [f for f in Pass.__dataclass_fields__ if f not in ARRAY_FIELDS and f != "mag_corrected"]
    return {name: getattr(observed, name) for name in names}


def inject(template: Pass, model, truth: Mapping[str, float], *, noise_mag: float, rng: np.random.Generator,
           offset_mag: float = 0.0, label: str = "synthetic") -> Pass:
    """A pass whose magnitudes are `model` at `truth`, shifted by `offset_mag`, plus noise.

    Parameters
    ----------
    template : Pass
        Supplies times, site, band, exposure and element set; `model` must have been built on
        the same times (every sample of `template`).
    model : SpinStateModel
        The forward model.
    truth : mapping
        Parameter values the model reads.
    noise_mag : float
        Standard deviation of the Gaussian noise, also written as every sample's error.
    rng : numpy.random.Generator
    offset_mag : float
        Constant added to every magnitude (an unknown zero point for the fit).
    label : str
        Becomes the source name, with a hash of the magnitudes.

    Returns
    -------
    Pass
        Valid, unsaturated samples; `mag_corrected` None; flux NaN.
    """
    if model.n != len(template):
        raise ValueError(f"the model has {model.n} samples but the template pass {len(template)}; "
                         "build the model on the template's times")
    if not noise_mag > 0:
        raise ValueError(f"noise_mag={noise_mag!r} must be positive (it is also the quoted error)")
    clean = model.magnitudes(truth) + offset_mag
    if not np.all(np.isfinite(clean)):
        raise ValueError("the model predicts an invisible object at some samples for these truths; "
                         "choose other values or a window where the object is lit")
    n = len(template)
    mag = clean + noise_mag * rng.standard_normal(n)
    digest = hashlib.sha256(mag.tobytes()).hexdigest()
    return template.replace(
        mag=mag, mag_err=np.full(n, float(noise_mag)), flux=np.full(n, np.nan), flux_err=np.full(n, np.nan),
        saturated=np.zeros(n, dtype=bool), valid=np.ones(n, dtype=bool), mag_corrected=None,
        source_name=f"{label}-{digest[:12]}", source_sha256=digest, source_format="synthetic", reduction=None)
