"""Injection-recovery coverage of the spin-state fit: do the 68% intervals hold the truth 68% of the time?

    python bench/fit_coverage.py                     # 20 truths, TOPEX model; recorded by bench/record.py
    python bench/fit_coverage.py --shape lopsided --truths 40
    python bench/fit_coverage.py --truths 4 --steps 200 --no-record
    python bench/fit_coverage.py --cycles --truths 10   # passes rendered by Blender Cycles (below)

Each trial draws a truth from the fit's own prior (the published five parameters plus the
jitter term), renders it with the same model and renderer the fit uses on 30 s of the real
TOPEX pass geometry (2024-07-30, Derenivka), adds Gaussian noise (quoted error 0.02 mag, plus
the truth's jitter), fits it, and checks whether each parameter's 16-84% interval holds the
truth. Drawing truths from the prior makes this a calibration test (simulation-based
calibration): for a correct likelihood and a sampler that explores the whole posterior, every
parameter's coverage is 68% on average over draws; with N truths the count is binomial, so the
3-sigma band is 0.68 +- 3 sqrt(0.68 * 0.32 / N) (0.37-0.99 for N = 20, 0.48-0.88 for N = 50).
The acceptance band asked of the project is 50-85%.

Trials run in a process pool (one per core); each is seeded, so a run is reproducible.

``--cycles``: validation free of the inverse crime. The passes are rendered by Blender Cycles
(`raycast.cycles`, the published workflow's renderer) from the published workflow's own COSMOS
2502 mesh (../shared/data/models/cosmos2502_lotos.obj and its materials JSON), not by the
project's renderer: 120 s windows at 5 fps (0.2 s exposures, 600 samples) of real COSMOS 2502
passes over Derenivka computed from its TLE (sunlit, elevation above 25 deg, the Sun below -8 deg
at the site), spin states drawn from the prior below, half spinning end over end (body x, the
paper's COSMOS 2502 axis) and half about the tube (body z, the paper's TOPEX axis), magnitudes at
1000 km plus 0.02 mag Gaussian noise. Each is fitted with the project's cached renderer of the
same mesh (the shape cache built once and shared, `rsodb.fit.shape_store`). Reported: every
parameter's 68% and 95% interval coverage, the mean bias in units of the posterior sigma, and
the residual RMS at the best fit against the injected noise. The rendered passes and their truths
are written to ``--passes-dir`` (default ~/.cache/rsodb/cycles_passes; never data_samples) and
reused when present; ``--render-only`` stops after rendering. Cycles renders at
``--cycles-resolution`` px across the footprint with ``--cycles-samples`` samples per pixel in
two passes of different seeds, so every frame's Cycles noise is measured and reported.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench.record import command, figure, portable, record, today  # noqa: E402

SHARED = ROOT.parent / "shared" / "data"
TOPEX_PHV = SHARED / "observations" / "result_22076_20240730_UT212240.phV"
FIGURE = ROOT / "docs" / "img" / "fit_coverage.png"
CYCLES_FIGURE = ROOT / "docs" / "img" / "fit_coverage_cycles.png"
BAND = (0.50, 0.85)

# -- the Cycles mode --------------------------------------------------------------------------
PAPER_OBJ = SHARED / "models" / "cosmos2502_lotos.obj"
PAPER_MATERIALS = SHARED / "models" / "cosmos2502_lotos.materials.json"
TLES = SHARED / "tle" / "tles.txt"
COSMOS_2502 = 40358
PASSES_DIR = Path.home() / ".cache" / "rsodb" / "cycles_passes"
NOISE_MAG = 0.02
# Frames whose Cycles noise is above a quarter of the injected noise (it would add more than 3% to
# it) are rendered again with CYCLES_REFINE times the samples, up to CYCLES_REFINE_ROUNDS times;
# what noise is left goes into the samples' quoted errors (load_cycles_pass).
CYCLES_NOISE_LIMIT_MAG = NOISE_MAG / 4.0
CYCLES_REFINE, CYCLES_REFINE_ROUNDS = 4, 2
WINDOW_S, CADENCE_S = 120.0, 0.2
# Spin states are drawn from, and fitted with, these priors (around the published COSMOS 2502
# state: P 40.5 s, P_pr 1620 s, theta 7 deg); the jitter is fitted only.
CYCLES_PRIORS = {
    "spin_period_s": {"kind": "uniform", "low": 36.0, "high": 45.0},
    "precession_period_s": {"kind": "uniform", "low": 600.0, "high": 3000.0},
    "precession_angle_deg": {"kind": "uniform", "low": 0.0, "high": 45.0},
    "jitter_mag": {"kind": "uniform", "low": 0.0, "high": 0.1},
}
# A phase is scored modulo a turn of the body that changes the model's light curve at the truth by
# less than a quarter of the injected noise (the tube turned 180 deg about its axis on axis-z passes).
LOOK_ALIKE_MAG = NOISE_MAG / 4
TARGETS = {"coverage95": 0.85, "bias_sigma": 1.0, "rms_over_noise": 1.5}


def config_record(
    shape: str,
    steps: int,
    walkers: int,
    init: str = "search",
    moves: str = "de",
    search_popsize: int = 15,
    search_maxiter: int = 100,
) -> dict:
    return {
        "name": "coverage",
        "model": {"shape": shape, "n_sub": 1},
        "parameters": {
            "spin_period_s": {"kind": "uniform", "low": 9.76, "high": 9.96},
            "precession_period_s": {"kind": "uniform", "low": 200.0, "high": 3000.0},
            "jitter_mag": {"kind": "uniform", "low": 0.0, "high": 0.03},
        },
        "sampler": {
            "n_walkers": walkers,
            "n_steps": steps,
            "init": init,
            "moves": moves,
            "search_popsize": search_popsize,
            "search_maxiter": search_maxiter,
        },
    }


def cycles_config(axis: str, args=None) -> dict:
    """The fit of a Cycles-rendered pass: the paper's mesh from its file, the spin axis it was
    rendered with; ``args`` (a namespace; bench/fit.py's and the pass rendering give fewer or
    none) sets the sampler, this script's command-line defaults the rest."""
    defaults = vars(command_line().parse_args([]))
    args = argparse.Namespace(**{**defaults, **(vars(args) if args is not None else {})})
    sampler = {
        "n_walkers": args.walkers,
        "n_steps": args.steps,
        "moves": args.moves,
        "until_converged": args.until_converged,
        "time_limit_s": args.time_limit_s,
        "search_points": 120,
        "search_popsize": args.search_popsize,
        "search_maxiter": args.search_maxiter,
    }
    if args.init != "search":  # (only when asked: the default start's configuration is as it was)
        sampler.update(init=args.init, search_starts=args.search_starts, search_polish=args.search_polish)
    config = {
        "name": "cycles",
        "band_draws": 0,
        "model": {"mesh": str(PAPER_OBJ), "materials": str(PAPER_MATERIALS), "spin_axis": axis, "n_sub": 1},
        "data": {"max_points": args.max_points},
        "parameters": CYCLES_PRIORS,
        "sampler": sampler,
    }
    if args.cache_accuracy_mag:  # (only when asked: the default model is as it was)
        config["model"]["accuracy_mag"] = args.cache_accuracy_mag
    if args.cache_grid_size:
        config["model"]["grid_size"] = args.cache_grid_size
    if args.cache_element_size_m:
        config["model"]["element_size_m"] = args.cache_element_size_m
    if args.cache_normal_bins:
        config["model"]["normal_bins_per_step"] = args.cache_normal_bins
    if args.correlation_time_s:  # (only when asked: the default likelihood is as it was)
        config["likelihood"] = {"correlation_time_s": args.correlation_time_s}
    if args.flux_error:
        config.setdefault("likelihood", {})["flux_error"] = True
    return config


def find_windows(satellite, site, count: int) -> list:
    """`count` starts of 120 s windows in real passes: sunlit, elevation > 25 deg, Sun below -8 deg at the site."""
    from raycast.geometry import PassGeometry

    epoch = np.datetime64(satellite.epoch_utc, "s")
    times = epoch - np.timedelta64(10, "D") + np.arange(0, 20 * 86400, 20).astype("timedelta64[s]")
    geometry = PassGeometry.compute(satellite, site, times, 0.0, n_sub=1)
    site_gcrs = geometry.sat_gcrs_km + geometry.range_km[:, None] * geometry.obs_gcrs[:, 0]
    zenith = site_gcrs / np.linalg.norm(site_gcrs, axis=1, keepdims=True)
    sun_altitude = np.degrees(np.arcsin(np.einsum("ij,ij->i", zenith, geometry.sun_gcrs[:, 0])))
    good = np.flatnonzero((geometry.el_deg > 25) & (geometry.sunlit_fraction > 0.99) & (sun_altitude < -8))
    runs = [r for r in np.split(good, np.flatnonzero(np.diff(good) > 1) + 1) if (r.size - 1) * 20 >= WINDOW_S]
    starts = [
        [times[r[0]] + np.timedelta64(int(k), "s") for k in range(0, (r.size - 1) * 20 - 120 + 1, 60)] for r in runs
    ]
    chosen = []
    while len(chosen) < count and any(starts):
        for run in starts:
            if run and len(chosen) < count:
                chosen.append(run.pop(len(run) // 2))
    if len(chosen) < count:
        raise RuntimeError(f"found {len(chosen)} windows of real passes, {count} asked; widen the search")
    return chosen


def terminator_offsets_note() -> str:
    """Make Cycles start shadow rays from the mesh itself (object terminator offsets 0), and say how.

    The wrapper sets them on ``object.cycles``, which Blender 5 no longer reads; until it sets
    the ``Object`` properties, the bench sets them too, on the in-process worker.
    """
    import raycast.cycles._worker as worker

    source = Path(worker.__file__).read_text()
    if "model.shadow_terminator_geometry_offset" in source:
        return "object terminator offsets 0, set by raycast.cycles"
    original = worker._add_mesh

    def add_mesh(scene, job):
        model = original(scene, job)
        model.shadow_terminator_geometry_offset = 0.0
        model.shadow_terminator_shading_offset = 0.0
        return model

    worker._add_mesh = add_mesh
    return (
        "object terminator offsets 0 set by this bench on Blender's Object (raycast.cycles on main sets "
        "object.cycles.*, which Blender 5 ignores); rendered in process"
    )


def render_cycles_passes(directory: Path, count: int, seed: int, resolution: int, samples: int) -> list[dict]:
    """Render (or reuse) `count` passes with Cycles; the records of truths.json."""
    import json

    from ingest.site import DERENIVKA
    from raycast.cycles import CyclesMesh, CyclesSettings, render_cycles
    from raycast.geometry import PassGeometry
    from raycast.geometry.orbit import Satellite
    from raycast.renderer.photometry import magnitude
    from rsodb.fit.config import FitConfig
    from rsodb.fit.model import ConvexFacets, SpinStateModel

    directory.mkdir(parents=True, exist_ok=True)
    index_path = directory / "truths.json"
    records = json.loads(index_path.read_text()) if index_path.exists() else []
    satellite = Satellite.from_catalogue(TLES, COSMOS_2502)
    windows = find_windows(satellite, DERENIVKA, count)
    mesh = CyclesMesh.from_obj(PAPER_OBJ, PAPER_MATERIALS)
    note = terminator_offsets_note()
    process = "subprocess" if note.endswith("raycast.cycles") else "in_process"
    settings = CyclesSettings(samples=samples, resolution=resolution, seed=seed, noise_passes=2, process=process)
    for i in range(len(records), count):
        rng = np.random.default_rng([seed, i])
        axis = "x" if i % 2 == 0 else "z"
        times = windows[i] + (np.arange(round(WINDOW_S / CADENCE_S)) * CADENCE_S * 1e9).astype("timedelta64[ns]")
        geometry = PassGeometry.compute(satellite, DERENIVKA, times, CADENCE_S, n_sub=1)
        space = FitConfig.from_dict(cycles_config(axis)).parameter_space({})
        frame = SpinStateModel(geometry, ConvexFacets.box(), "precessing", {"spin_axis": axis}, (), "V", 1000.0)
        started = time.perf_counter()
        for attempt in range(20):
            truth = {k: v for k, v in space.values(space.sample_prior(rng, 1)[0]).items() if k != "jitter_mag"}
            body = geometry.body_frame(frame.attitude_model(truth))
            result = render_cycles(mesh, body.sun_body[:, 0], body.obs_body[:, 0], settings, progress=False)
            intensity = result.intensity_m2_sr * body.sunlit[:, 0]
            if np.all(intensity > 0):
                break
            print(f"pass {i}: truth {attempt} leaves the object dark in some frames; drawing another")
        noise_mag = 2.5 / np.log(10) * result.noise_rel
        intensity, noise_mag, refined = refine_noisy_frames(
            mesh,
            body,
            settings,
            intensity,
            noise_mag,
            lambda sun, obs, s: render_cycles(mesh, sun, obs, s, progress=False),
        )
        clean = magnitude(intensity, 1000.0, "V")
        mag = clean + NOISE_MAG * rng.standard_normal(clean.size)
        name = f"cycles_{i:02d}.npz"
        np.savez(
            directory / name,
            time_utc=times.astype("datetime64[ns]").view("i8"),
            mag=mag,
            clean_mag=clean,
            intensity_m2_sr=intensity,
            cycles_noise_mag=noise_mag,
            az_deg=geometry.az_deg,
            el_deg=geometry.el_refracted_deg,
            range_km=geometry.range_km,
        )
        records.append(
            {
                "file": name,
                "index": i,
                "axis": axis,
                "truth": truth,
                "start_utc": str(times[0]),
                "tle": list(satellite.tle),
                "cycles": {
                    "resolution_px": resolution,
                    "samples_per_px": samples,
                    "noise_passes": 2,
                    "terminator": note,
                    "refined_frames": refined,
                    "noise_mag_rms": float(np.sqrt(np.mean(noise_mag**2))),
                    "noise_mag_max": float(np.max(noise_mag)),
                    "seconds": time.perf_counter() - started,
                    "cpu_seconds_per_frame": result.cpu_seconds_per_frame,
                },
            }
        )
        index_path.write_text(json.dumps(records, indent=1))
        print(
            f"pass {i} ({axis}, start {times[0]}): rendered in {records[-1]['cycles']['seconds']:.0f} s, "
            f"Cycles noise {records[-1]['cycles']['noise_mag_rms']:.4f} mag RMS "
            f"(max {records[-1]['cycles']['noise_mag_max']:.4f})",
            flush=True,
        )
    return records[:count]


def refine_noisy_frames(mesh, body, settings, intensity, noise_mag, render):
    """Render again, with CYCLES_REFINE x the samples each round, the frames whose Cycles noise
    (the two passes' standard error) is above CYCLES_NOISE_LIMIT_MAG: glint frames, where a few
    bright pixels decide the frame, converge far slower than the rest. Returns the intensities,
    their noise (mag) and {samples per pixel: frames rendered again}."""
    from dataclasses import replace

    intensity, noise_mag = intensity.copy(), noise_mag.copy()
    refined = {}
    samples = settings.samples
    for _ in range(CYCLES_REFINE_ROUNDS):
        noisy = np.flatnonzero(noise_mag > CYCLES_NOISE_LIMIT_MAG)
        if noisy.size == 0:
            break
        samples *= CYCLES_REFINE
        finer = render(body.sun_body[noisy, 0], body.obs_body[noisy, 0], replace(settings, samples=samples))
        intensity[noisy] = finer.intensity_m2_sr * body.sunlit[noisy, 0]
        noise_mag[noisy] = 2.5 / np.log(10) * finer.noise_rel
        refined[str(samples)] = int(noisy.size)
    return intensity, noise_mag, refined


def load_cycles_pass(directory: Path, record: dict):
    """The `Pass` of one rendered record (what a ccd_phot file of it would read as)."""
    from ingest.observation import Pass
    from ingest.site import DERENIVKA

    data = np.load(directory / record["file"])
    n = data["mag"].size
    return Pass(
        norad=COSMOS_2502,
        name="COSMOS 2502 (Cycles)",
        band="V",
        site=DERENIVKA,
        exposure_s=CADENCE_S,
        time_utc=data["time_utc"].view("datetime64[ns]"),
        mag=data["mag"],
        # The injected noise and Cycles' own (its two passes' standard error): both are the data's.
        mag_err=np.hypot(NOISE_MAG, data["cycles_noise_mag"]),
        flux=np.full(n, np.nan),
        flux_err=np.full(n, np.nan),
        az_deg=data["az_deg"],
        el_deg=data["el_deg"],
        range_km=data["range_km"],
        saturated=np.zeros(n, dtype=bool),
        valid=np.ones(n, dtype=bool),
        tle=tuple(record["tle"]),
        mag_convention="standard magnitude reduced to 1000 km range (rendered by Blender Cycles)",
        source_name=record["file"],
        source_format="synthetic",
    )


def _cycles_task(task):
    from rsodb.fit.config import FitConfig
    from rsodb.fit.coverage import recover_observed
    from rsodb.fit.shape_store import ShapeStore

    directory, record, config_record, chain_dir, store_dir = task
    observed = load_cycles_pass(Path(directory), record)
    return recover_observed(
        observed,
        FitConfig.from_dict(config_record),
        record["truth"],
        int(record["index"]),
        chain_dir=chain_dir,
        store=ShapeStore(store_dir),
        look_alike_mag=LOOK_ALIKE_MAG,
    )


def correlation_time_s(series: np.ndarray, cadence_s: float) -> float:
    """Where the autocorrelation of an evenly sampled series first falls below 1/e, in seconds:
    how long a model error stays alike from sample to sample."""
    centred = series - series.mean()
    acf = np.correlate(centred, centred, "full")[centred.size - 1 :] / np.dot(centred, centred)
    below = np.flatnonzero(acf < np.exp(-1.0))
    return float(below[0] * cadence_s) if below.size else float(centred.size * cadence_s)


def forward_model_at_truth(directory: Path, records: list[dict], argv, args) -> int:
    """The project's direct renderer of the paper mesh, and the fit's own model (the cached
    renderer of the same mesh, as a fit of `--cycles` builds it), against each Cycles pass's
    noiseless magnitudes at the true state: how far the fit's forward model is from the data's
    renderer before any fitting (the floor of the residuals)."""
    from ingest.site import DERENIVKA
    from raycast.geometry import PassGeometry
    from raycast.geometry.orbit import Satellite
    from raycast.renderer import render
    from rsodb.fit.config import FitConfig
    from rsodb.fit.model import ConvexFacets, SpinStateModel
    from rsodb.fit.runner import FitProblem
    from rsodb.fit.shape_store import ShapeStore
    from rsodb.rendering import load_scene

    scene = load_scene(str(PAPER_OBJ), str(PAPER_MATERIALS))
    satellite = Satellite.from_catalogue(TLES, COSMOS_2502)
    rows = []
    for rec in records:
        data = np.load(directory / rec["file"])
        times = data["time_utc"].view("datetime64[ns]")
        geometry = PassGeometry.compute(satellite, DERENIVKA, times, CADENCE_S, n_sub=1)
        frame = SpinStateModel(geometry, ConvexFacets.box(), "precessing", {"spin_axis": rec["axis"]}, (), "V", 1000.0)
        body = geometry.body_frame(frame.attitude_model(rec["truth"]))
        # 0.005 mag where the renderer reaches it within its pixel budget, else 0.01 (it says which).
        try:
            accuracy = 0.005
            ours = render(scene, body, method="direct", band="V", accuracy_mag=accuracy).mag_1000km
        except ValueError:
            accuracy = 0.01
            ours = render(scene, body, method="direct", band="V", accuracy_mag=accuracy).mag_1000km
        difference = ours - data["clean_mag"]
        finite = np.isfinite(difference)
        difference = difference[finite] - np.median(difference[finite])
        rms, worst = float(np.sqrt(np.mean(difference**2))), float(np.max(np.abs(difference)))
        problem = FitProblem.build(
            load_cycles_pass(directory, rec),
            FitConfig.from_dict(cycles_config(rec["axis"], args)),
            store=ShapeStore(str(directory / "shapes")),
        )
        # The settings of the cache this fit really built (the same for every pass).
        cache_accuracy, cache_grid = problem.config.model.accuracy_mag, problem.posterior.model.brightness.grid_size
        cache_element_mm = 1000.0 * problem.posterior.model.brightness.element_size_m
        values = dict(problem.posterior.space.fixed, **rec["truth"])
        cached = problem.posterior.model.magnitudes(values) - data["clean_mag"]
        cached = cached[np.isfinite(cached)] - np.median(cached[np.isfinite(cached)])
        fit_rms, fit_worst = float(np.sqrt(np.mean(cached**2))), float(np.max(np.abs(cached)))
        rows.append((rec, rms, worst, float(np.ptp(data["clean_mag"])), accuracy, fit_rms, fit_worst))
        print(
            f"{rec['file']} axis {rec['axis']}: project - Cycles at the truth {rms:.4f} mag RMS (max {worst:.3f}; "
            f"direct renderer at {accuracy} mag); the fit's cached model {fit_rms:.4f} (max {fit_worst:.3f}, "
            f"correlated over {correlation_time_s(cached, CADENCE_S):.1f} s)",
            flush=True,
        )
    if args.no_record:
        return 0
    table = "\n".join(
        f"| {rec['file']} | {rec['axis']} | {rec['truth']['spin_period_s']:.2f} | {rec['truth']['precession_angle_deg']:.1f} | "
        f"{swing:.2f} | {rec['cycles']['noise_mag_rms']:.4f} | {accuracy} | {rms:.4f} | {worst:.3f} | "
        f"{fit_rms:.4f} | {fit_worst:.3f} |"
        for rec, rms, worst, swing, accuracy, fit_rms, fit_worst in rows
    )
    axes = sorted({rec["axis"] for rec, *_ in rows})
    by_axis = {axis: float(np.median([row[1] for row in rows if row[0]["axis"] == axis])) for axis in axes}
    fit_by_axis = {axis: float(np.median([row[5] for row in rows if row[0]["axis"] == axis])) for axis in axes}
    variant = f", elements up to {cache_element_mm:.0f} mm" if args.cache_element_size_m else ""
    if args.cache_normal_bins:
        variant += f", {args.cache_normal_bins:g} normal bins a step"
    section = f"""
## The fit's forward model against Cycles at the true state{variant} ({today()}, bench/fit_coverage.py --cycles --at-truth)

The project's direct renderer of the published workflow's COSMOS 2502 mesh (accuracy 0.005 mag,
0.01 where its pixel budget cannot reach 0.005), and the fit's own model of it (the cached renderer
as a `--cycles` fit builds it: tables to {cache_accuracy} mag, cube map of {cache_grid}, elements up to
{cache_element_mm:.0f} mm),
against the noiseless magnitudes Blender Cycles rendered of the same mesh along {len(rows)} passes of
`--cycles` (120 s, 600 frames each), at the true spin state, after the median offset: the floor
under any fit's residuals, before noise (0.02 mag) and before fitting.

| pass | spin axis | P (s) | cone (deg) | swing (mag) | Cycles noise (mag RMS) | direct accuracy asked (mag) | direct - Cycles (mag RMS) | max (mag) | fit's cached model - Cycles (mag RMS) | max (mag) |
|---|---|---|---|---|---|---|---|---|---|---|
{table}

Median RMS by spin axis, direct renderer: {", ".join(f"{axis}: {value:.4f} mag" for axis, value in by_axis.items())};
the fit's cached model: {", ".join(f"{axis}: {value:.4f} mag" for axis, value in fit_by_axis.items())}.
Reproduce: `{command("fit_coverage.py", argv)}`.
"""
    figures = [
        figure(
            f"direct renderer - Cycles at the truth, axis {axis} (median RMS)", f"{value:.4f} mag", "<= 0.02 mag noise"
        )
        for axis, value in by_axis.items()
    ] + [
        figure(
            f"fit's cached model - Cycles at the truth, axis {axis} (median RMS)",
            f"{value:.4f} mag",
            "<= 0.02 mag noise",
        )
        for axis, value in fit_by_axis.items()
    ]
    # A cache of other elements is its own benchmark: the default's figures stay beside it.
    name = (
        f"fit_forward_vs_cycles_elements_{cache_element_mm:.0f}mm"
        if args.cache_element_size_m
        else "fit_forward_vs_cycles"
    ) + (f"_normal_bins_{args.cache_normal_bins:g}" if args.cache_normal_bins else "")
    record(name, command("fit_coverage.py", argv), figures, section)
    return 0


def _journal_key(record: dict, config: dict) -> str:
    """A fit's key in the journal: the pass, its truth, the fit's settings and the forward model's
    code (`rsodb.fit.shape_store.code_fingerprint`), so a change to the renderer fits again."""
    import hashlib
    import json

    from rsodb.fit.shape_store import code_fingerprint

    text = json.dumps(
        {
            "file": record["file"],
            "truth": record["truth"],
            "cycles": {k: v for k, v in record["cycles"].items() if k not in ("seconds", "cpu_seconds_per_frame")},
            "config": config,
            "forward_model": code_fingerprint(),
        },
        sort_keys=True,
    )
    return hashlib.sha256(text.encode()).hexdigest()


def load_journal(journal: Path, records: list[dict], configs: list[dict]) -> dict:
    """Fits already in `journal` for these passes and settings, by pass index."""
    import json

    from rsodb.fit.coverage import Recovery

    if not journal.exists():
        return {}
    wanted = {_journal_key(r, c): int(r["index"]) for r, c in zip(records, configs)}
    done = {}
    for line in journal.read_text().splitlines():
        try:
            entry = json.loads(line)
        except json.JSONDecodeError:  # a line cut by a killed run
            continue
        if entry.get("key") in wanted:
            done[wanted[entry["key"]]] = Recovery(**entry["recovery"])
    return done


def append_journal(journal: Path, record: dict, config: dict, recovery) -> None:
    import json

    entry = {"key": _journal_key(record, config), "index": int(record["index"]), "recovery": vars(recovery)}
    with open(journal, "a") as handle:
        handle.write(json.dumps(entry, default=float) + "\n")


class _DirectBrightness:
    """The direct renderer behind a fit's forward model (``intensity(sun, obs)``). Its first call
    chooses the pixels: those of 0.005 mag, else of 0.01, else the mesh radius / 150 (the render
    benchmark's reference) where a glint or shadow edge keeps even 0.01 out of reach; later calls
    keep them, so two states are compared with one renderer. ``settings`` says which it took."""

    def __init__(self, scene):
        self.scene = scene
        self.accuracy_mag, self.pixel_size_m = 0.01, None
        self.settings = ""

    def intensity(self, sun, obs, **parameters):
        from raycast.renderer.direct import AccuracyOutOfReach
        from raycast.renderer.methods import METHODS

        if self.pixel_size_m is None:
            self.pixel_size_m = self.scene.posed().radius_m / 150.0
            self.settings = f"{1000 * self.pixel_size_m:.1f} mm pixels, radius / 150"
            for accuracy in (0.005, 0.01):
                try:
                    values, chosen = METHODS["direct"](self.scene, sun, obs, accuracy, None, None, False)
                except AccuracyOutOfReach:
                    continue
                self.accuracy_mag, self.pixel_size_m = accuracy, chosen["pixel_size_m"]
                self.settings = f"{accuracy} mag: {1000 * self.pixel_size_m:.1f} mm pixels"
                return values
        return METHODS["direct"](self.scene, sun, obs, self.accuracy_mag, None, self.pixel_size_m, False)[0]


def _truth_near(recovery, names) -> dict:
    """The truth as the fit's values: its look-alike nearest the median where an angle is scored
    modulo a look-alike turn, and the median's value of what was not injected (the jitter)."""
    values = {}
    for name in names:
        if name not in recovery.truth:
            values[name] = float(recovery.median[name])
            continue
        truth = float(recovery.truth[name])
        turn = (recovery.look_alike_turns or {}).get(name)
        if turn:
            truth += turn * round((float(recovery.median[name]) - truth) / turn)
        values[name] = truth
    return values


def diagnose_fits(directory: Path, records: list[dict], argv, args) -> int:
    """Whose miss is it, the forward model's or the sampler's? For every pass fitted with these
    settings (the journal), ln L at the fit's posterior median minus ln L at the truth, under the
    fit's cached model and under the direct renderer of the same mesh. Where the model holds,
    2 (ln L(best) - ln L(truth)) is chi-square with one degree per free parameter; a median far
    above the truth under the cached model but not under the direct one means the cached
    model's own error moved the fit."""
    import dataclasses

    from scipy.stats import chi2

    from raycast.renderer.cache import SceneCache
    from rsodb.fit.config import FitConfig
    from rsodb.fit.runner import FitProblem
    from rsodb.fit.shape_store import ShapeStore

    configs = [cycles_config(record["axis"], args) for record in records]
    done = load_journal(directory / "recoveries.jsonl", records, configs)
    if not done:
        print(
            f"no pass is fitted with these settings yet ({directory / 'recoveries.jsonl'}); give the "
            "settings of a coverage run that finished",
            file=sys.stderr,
        )
        return 1
    rows = []
    for rendered, config in zip(records, configs):
        recovery = done.get(int(rendered["index"]))
        if recovery is None:
            continue
        problem = FitProblem.build(
            load_cycles_pass(directory, rendered),
            FitConfig.from_dict(config),
            store=ShapeStore(str(directory / "shapes")),
        )
        posterior = problem.posterior
        if not isinstance(posterior.model.brightness, SceneCache):
            raise SystemExit(
                f"--diagnose needs the fit's cached renderer, not {type(posterior.model.brightness).__name__}"
            )
        names = posterior.space.names
        median = np.array([float(recovery.median[n]) for n in names])
        truth_values = _truth_near(recovery, names)
        truth = np.array([truth_values[n] for n in names])
        direct_brightness = _DirectBrightness(posterior.model.brightness.scene)
        direct = dataclasses.replace(
            posterior, model=dataclasses.replace(posterior.model, brightness=direct_brightness)
        )
        started = time.process_time()
        # The truth first: the direct renderer chooses its pixels there.
        gains = [-p.log_likelihood(truth) + p.log_likelihood(median) for p in (posterior, direct)]
        misses = [n for n, inside in recovery.covered95.items() if not inside]
        rows.append((rendered, gains, direct_brightness.settings, misses, time.process_time() - started))
        print(
            f"pass {rendered['index']} ({rendered['axis']}): ln L(median) - ln L(truth): cached model {gains[0]:+.1f}, "
            f"direct renderer ({direct_brightness.settings}; {rows[-1][4]:.0f} s of CPU for the four light curves) "
            f"{gains[1]:+.1f}; outside 95%: {', '.join(misses) or '-'}",
            flush=True,
        )
    free = len(names)
    limit = 0.5 * float(chi2.ppf(0.95, free))
    beyond = [sum(row[1][k] > limit for row in rows) for k in (0, 1)]
    summary = (
        f"ln L(median) - ln L(truth) beyond {limit:.1f} (half the 95% point of chi-square with {free} degrees): "
        f"cached model {beyond[0]} of {len(rows)} passes, direct renderer {beyond[1]} of {len(rows)}"
    )
    print(summary)
    if args.no_record:
        return 0
    table = "\n".join(
        f"| {rec['index']} | {rec['axis']} | {gains[0]:+.1f} | {gains[1]:+.1f} | {settings} | {cpu:.0f} | "
        f"{', '.join(misses) or '-'} |"
        for rec, gains, settings, misses, cpu in rows
    )
    section = f"""
## Whose miss: the cached model's or the sampler's? ({today()}, bench/fit_coverage.py --cycles --diagnose)

For each Cycles pass of the coverage run with these settings (its journal), the log-likelihood
of the fit's posterior median minus that of the truth, under the fit's own forward model (the
cached renderer) and under the project's direct renderer of the same mesh (the same likelihood,
jitter at the fit's median, the truth's look-alike phase nearest the median where the phase is
scored modulo a look-alike turn). Where a model holds, 2 (ln L(best) - ln L(truth)) is
chi-square with {free} degrees of freedom, so values above {limit:.1f} are rare (5%); the median is
not the best point, so it may also fall below the truth. A pass far above under the cached model
and not under the direct renderer was moved by the cached model's own error, not by the sampler.

| pass | spin axis | cached model | direct renderer | direct renderer's setting | CPU s (4 light curves) | outside the fit's 95% |
|---|---|---|---|---|---|---|
{table}

{summary}.
Reproduce: `{command("fit_coverage.py", argv)}`.
"""
    figures = [
        figure(
            "passes where the cached model prefers the fit's median by > chi2 95%", f"{beyond[0]} of {len(rows)}", ""
        ),
        figure("the same under the direct renderer", f"{beyond[1]} of {len(rows)}", ""),
    ]
    record("fit_coverage_diagnosis", command("fit_coverage.py", argv), figures, section)
    return 0


def run_cycles(args, argv) -> int:
    """The Cycles mode: render (or reuse) the passes, fit each, report coverage and bias."""
    import json

    from rsodb.fit.coverage import coverage_table
    from rsodb.pool import imap_in_pool

    directory = Path(args.passes_dir)
    records = render_cycles_passes(directory, args.truths, args.seed, args.cycles_resolution, args.cycles_samples)
    if args.render_only:
        return 0
    if args.at_truth:
        return forward_model_at_truth(directory, records, argv, args)
    if args.diagnose:
        return diagnose_fits(directory, records, argv, args)
    started = time.perf_counter()
    configs = [cycles_config(record["axis"], args) for record in records]
    # Each finished fit is appended to a journal at once, so a run that is stopped keeps its fits and
    # the next run with the same settings and forward-model code fits only the passes still missing.
    journal = directory / "recoveries.jsonl"
    if args.passes:
        chosen = set(args.passes)
        unknown = sorted(chosen - {int(r["index"]) for r in records})
        if unknown:
            print(f"--passes {unknown}: no such pass (there are {len(records)}, 0-{len(records) - 1})", file=sys.stderr)
            return 2
        records, configs = zip(*[(r, c) for r, c in zip(records, configs) if int(r["index"]) in chosen])
    done = load_journal(journal, records, configs)
    if done:
        print(f"{len(done)} of {len(records)} passes already fitted with these settings ({journal})")
    rendered = len(records)
    if args.journal_only:
        records = [record for record in records if int(record["index"]) in done]
        if not records:
            print(f"no pass is fitted with these settings yet ({journal}); run without --journal-only", file=sys.stderr)
            return 1
    from_journal = len(done)
    with tempfile.TemporaryDirectory() as scratch:
        tasks = [
            (str(directory), record, config, scratch, str(directory / "shapes"))
            for record, config in zip(records, configs)
            if int(record["index"]) not in done
        ]
        # The first fit builds the shape cache; the others wait for it (one lock per key).
        for task, recovery in zip(
            tasks,
            imap_in_pool(
                _cycles_task, tasks, processes=args.processes, description="Cycles passes", ordered=True, chunksize=1
            ),
        ):
            append_journal(journal, task[1], task[2], recovery)
            done[int(task[1]["index"])] = recovery
    recoveries = [done[int(record["index"])] for record in records]
    elapsed = time.perf_counter() - started
    fit_minutes = sum(r.elapsed_s for r in recoveries) / 60
    (directory / "recoveries.json").write_text(
        json.dumps([dict(vars(r), covered95=r.covered95) for r in recoveries], indent=1, default=float)
    )
    names = [n for n in recoveries[0].covered if n != "jitter_mag"]
    table68, table95 = coverage_table(recoveries), coverage_table(recoveries, 95)
    bias = {n: float(np.mean([r.bias_sigma[n] for r in recoveries])) for n in names}
    ratio = np.array([r.residual_rms_mag / NOISE_MAG for r in recoveries])
    # The data's own noise: the injected and Cycles' (its two seeds' standard error), which no
    # model can fit away (a perfect model's residual RMS).
    data_noise = np.array([math.hypot(NOISE_MAG, rec["cycles"]["noise_mag_rms"]) for rec in records])
    ratio_data = np.array([r.residual_rms_mag for r in recoveries]) / data_noise
    rows = []
    for n in names:
        ok95 = table95[n] >= TARGETS["coverage95"]
        ok_bias = abs(bias[n]) < TARGETS["bias_sigma"]
        rows.append(
            f"| {n} | {table68[n]:.2f} | {table95[n]:.2f} {'' if ok95 else '(MISSED)'} | "
            f"{bias[n]:+.2f} {'' if ok_bias else '(MISSED)'} |"
        )
        print(f"{n:24s} 68%: {table68[n]:.2f}  95%: {table95[n]:.2f}  mean bias {bias[n]:+.2f} sigma")
    print(
        f"residual RMS / injected noise: median {np.median(ratio):.2f}, max {ratio.max():.2f}; / the data's noise: "
        f"median {np.median(ratio_data):.2f}, max {ratio_data.max():.2f}; {elapsed / 60:.0f} min (the fits' own time: {fit_minutes:.0f} min)"
    )
    per_pass = "\n".join(
        f"| {i} | {rec['axis']} | {rec['start_utc'][:19]} | {rec['truth']['spin_period_s']:.2f} | "
        f"{rec['truth']['precession_period_s']:.0f} | {rec['truth']['precession_angle_deg']:.1f} | "
        f"{rec['cycles']['noise_mag_rms']:.4f} | {r.residual_rms_mag:.4f} | {r.residual_rms_mag / noise:.2f} | "
        f"{r.autocorr_lengths:.0f} | "
        f"{', '.join(n for n in names if not r.covered95[n]) or '-'} |"
        for i, (rec, r, noise) in enumerate(zip(records, recoveries, data_noise))
    )
    for rec, r in zip(records, recoveries):
        missed = [n for n in names if not r.covered95[n]]
        print(
            f"pass {rec['index']}: RMS {r.residual_rms_mag:.4f} mag, {r.autocorr_lengths:.0f} tau, outside 95%: {missed or 'none'}"
        )
    if args.no_record or args.passes:
        if args.passes and not args.no_record:
            print("(some passes only: nothing recorded)")
        return 0
    coverage_figure(recoveries, CYCLES_FIGURE, names)
    load = os.getloadavg()
    cycles = records[0]["cycles"]
    worst95 = min(table95[n] for n in names)
    worst_bias = max(abs(bias[n]) for n in names)
    limits = f", at most {args.max_points} points (consecutive exposures binned)" if args.max_points else ""
    search = (
        f"multi-start: {args.search_starts} prior points screened, the best {args.search_polish} refined by Nelder-Mead"
        if args.init == "multistart"
        else f"differential evolution, population {args.search_popsize} per parameter, {args.search_maxiter} generations"
    )
    if args.time_limit_s:
        limits += f", each fit stopped after {args.time_limit_s:.0f} s (search included)"
    folded = [(i, r.look_alike_turns) for i, r in enumerate(recoveries) if getattr(r, "look_alike_turns", None)]
    folded_note = (
        "Phases scored modulo a look-alike turn (turning the true state by it changes the model's light curve "
        f"by less than {LOOK_ALIKE_MAG:.3f} mag RMS, so the data cannot tell the two apart): "
        + "; ".join(f"pass {i} " + ", ".join(f"{n} mod {t:.0f} deg" for n, t in turns.items()) for i, turns in folded)
        + "."
        if folded
        else "Every phase scored modulo its full turn (no look-alike turn found)."
    )
    model_text = forward_model_text(args)
    fitted_now = len(records) - from_journal
    wall_text = f"{elapsed / 60:.0f} min of wall time on {os.cpu_count()} cores"
    journal_text = f"{from_journal} taken from the journal of earlier runs with the same settings"
    if not from_journal:
        run_text = f"{wall_text} in the last run"
    elif fitted_now:
        run_text = f"{fitted_now} fitted in the last run ({wall_text}), {journal_text}"
    else:
        run_text = f"all {journal_text}"
    refined = [sum(r["cycles"].get("refined_frames", {}).values()) for r in records]
    refined_text = f"{sum(refined)} frame renders in {sum(1 for n in refined if n)} of {len(records)} passes"
    section = f"""
## Fit coverage on Cycles-rendered passes ({today()}, bench/fit_coverage.py --cycles)

{len(records)} passes{f" (of {rendered} rendered; the others not fitted yet)" if len(records) < rendered else ""} rendered by **Blender Cycles** (`raycast.cycles`) from the published workflow's own COSMOS
2502 mesh and materials, fitted with the project's cached renderer of that mesh{model_text} (no inverse crime:
the data are not the fit's own model). 120 s windows of real COSMOS 2502 passes over Derenivka (TLE
epoch 2024-01-09; sunlit, elevation > 25 deg, Sun below -8 deg), 5 fps, 0.2 s exposures (600 samples),
magnitudes at 1000 km plus {NOISE_MAG} mag Gaussian noise; spin states drawn from the fit's prior (P 36-45 s,
P_pr 600-3000 s, cone 0-45 deg, phases uniform), spin axis body x (end over end, the paper's COSMOS
2502 axis) for even passes and body z (the tube) for odd ones. Cycles: {cycles["resolution_px"]} px across
the footprint, {cycles["samples_per_px"]} samples/px in two seeds, {cycles["terminator"]}; frames whose
Cycles noise (the two seeds' standard error) is above {CYCLES_NOISE_LIMIT_MAG} mag rendered again with
{CYCLES_REFINE}x the samples, up to {CYCLES_REFINE_ROUNDS} times ({refined_text}); the noise left,
{np.median([r["cycles"]["noise_mag_rms"] for r in records]):.4f} mag RMS per frame (median over passes; max
{max(r["cycles"]["noise_mag_max"] for r in records):.4f}), is added in quadrature to each sample's quoted error. Fit: jitter free on 0-0.1 mag, {args.walkers} walkers,
{args.steps} steps{" until converged (at most)" if args.until_converged else ""} ({args.moves} moves), global search first ({search}){limits}. The fits took
{fit_minutes:.0f} min together, {run_text} (load average
{load[0]:.1f} at the end).

| parameter | 68% coverage | 95% coverage (target >= {TARGETS["coverage95"]}) | mean bias, posterior sigmas (target < {TARGETS["bias_sigma"]}) |
|---|---|---|---|
{chr(10).join(rows)}

Residual RMS over every sample at the best fit / injected noise: median {np.median(ratio):.2f}, worst
{ratio.max():.2f} (target <= {TARGETS["rms_over_noise"]}); / the data's noise (the injected {NOISE_MAG} mag and the
pass's Cycles noise in quadrature, which a perfect model leaves): median {np.median(ratio_data):.2f}, worst
{ratio_data.max():.2f}.

{folded_note}

| pass | axis | start (UTC) | P (s) | P_pr (s) | cone (deg) | Cycles noise (mag) | residual RMS (mag) | / data's noise | tau lengths | outside 95% |
|---|---|---|---|---|---|---|---|---|---|---|
{per_pass}

![truth's posterior quantile per parameter, Cycles passes](img/fit_coverage_cycles.png)

Reproduce: `{command("fit_coverage.py", portable(argv))}` (renders into `--passes-dir`, reused when present).
"""
    figures = [
        figure("worst parameter's 95% coverage", f"{worst95:.2f}", f">= {TARGETS['coverage95']}"),
        figure("largest mean bias", f"{worst_bias:.2f} sigma", f"< {TARGETS['bias_sigma']} sigma"),
        figure("residual RMS / injected noise (worst pass)", f"{ratio.max():.2f}", f"<= {TARGETS['rms_over_noise']}"),
        figure(
            "residual RMS / the data's noise, injected and Cycles' (worst pass)",
            f"{ratio_data.max():.2f}",
            f"<= {TARGETS['rms_over_noise']}",
        ),
        figure("passes", f"{len(records)}", ">= 10"),
    ]
    record("fit_coverage_cycles", command("fit_coverage.py", portable(argv)), figures, section)
    return 0


def forward_model_text(args) -> str:
    """The fit's forward-model settings that differ from the defaults, as a clause (or "")."""
    settings = []
    if args.cache_element_size_m:
        settings.append(f"surface elements up to {1000 * args.cache_element_size_m:.0f} mm (`[model] element_size_m`)")
    if args.cache_grid_size:
        settings.append(f"a {args.cache_grid_size}-node direction grid")
    if args.cache_normal_bins:
        settings.append(f"shading classes of {args.cache_normal_bins:g} a normal step (`[model] normal_bins_per_step`)")
    if args.cache_accuracy_mag:
        settings.append(f"a cache accuracy of {args.cache_accuracy_mag:g} mag")
    if args.correlation_time_s:
        settings.append(f"a model error correlated over {args.correlation_time_s:g} s")
    if args.flux_error:
        settings.append("a model error in flux")
    return f" with {', '.join(settings)}" if settings else ""


def coverage_figure(recoveries, path: Path, names=None) -> None:
    """Per parameter, the truth's quantile in its posterior for every truth (uniform if calibrated)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(names or recoveries[0].quantile)
    figure, axis = plt.subplots(figsize=(9.0, 3.8), dpi=110)
    rng = np.random.default_rng(0)
    for i, name in enumerate(names):
        quantile = np.array([r.quantile[name] for r in recoveries])
        # Coloured by the 16-84% interval of the summary (the table's count); the quantile of
        # the stored, thinned draws may put a borderline truth on the other side of 0.16/0.84.
        inside = np.array([r.covered[name] for r in recoveries])
        x = i + rng.uniform(-0.18, 0.18, quantile.size)
        axis.scatter(x[inside], quantile[inside], s=18, color="tab:blue", label="inside 16-84%" if i == 0 else None)
        axis.scatter(
            x[~inside], quantile[~inside], s=18, color="tab:red", marker="x", label="outside" if i == 0 else None
        )
        axis.text(i, 1.04, f"{inside.mean():.0%}", ha="center", va="bottom", fontsize=9)
    axis.axhspan(0.16, 0.84, color="0.92", zorder=0)
    axis.set_xticks(range(len(names)), [n.replace("_", " ") for n in names], rotation=20, ha="right", fontsize=8)
    axis.set_ylim(-0.03, 1.12)
    axis.set_ylabel("truth's quantile in its posterior")
    axis.set_title(
        f"Injection-recovery: {len(recoveries)} truths (calibrated: uniform on 0-1, 68% in the grey band)", fontsize=9
    )
    axis.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    figure.tight_layout()
    figure.savefig(path)
    plt.close(figure)


def command_line() -> argparse.ArgumentParser:
    """This script's arguments (their defaults are also a Cycles fit's, `cycles_config`)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truths", type=int, default=20)
    parser.add_argument("--shape", default="topex", help="model used to inject and fit (default topex)")
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--walkers", type=int, default=24)
    parser.add_argument("--samples", type=int, default=38, help="samples of the 30 s window used (default 38)")
    parser.add_argument("--init", default="search", help="walker start: search | multistart | population | prior")
    parser.add_argument("--search-starts", type=int, default=8192, help="multistart: prior points screened")
    parser.add_argument("--search-polish", type=int, default=16, help="multistart: best points refined")
    parser.add_argument("--moves", default="de", help="emcee moves: de | stretch")
    parser.add_argument("--search-popsize", type=int, default=15, help="search population per parameter (default 15)")
    parser.add_argument("--search-maxiter", type=int, default=100, help="search generations (default 100)")
    parser.add_argument("--processes", type=int, default=None)
    parser.add_argument("--save", metavar="FILE.json", help="also write every truth's recovery here")
    parser.add_argument("--no-record", action="store_true", help="print only; record nothing, draw no figure")
    cycles = parser.add_argument_group("Cycles mode")
    cycles.add_argument("--cycles", action="store_true", help="passes rendered by Blender Cycles from the paper mesh")
    cycles.add_argument("--passes-dir", default=str(PASSES_DIR), help=f"rendered passes (default {PASSES_DIR})")
    cycles.add_argument("--render-only", action="store_true", help="render the passes, fit nothing")
    cycles.add_argument(
        "--journal-only",
        action="store_true",
        help="report the passes already fitted with these settings (the journal), fit nothing",
    )
    cycles.add_argument(
        "--at-truth",
        action="store_true",
        help="compare the project's renderer with Cycles at the true states, fit nothing",
    )
    cycles.add_argument(
        "--diagnose",
        action="store_true",
        help="for the passes fitted with these settings: ln L at the fit's median minus at the truth, "
        "under the cached model and the direct renderer (is a miss the model's or the sampler's?)",
    )
    cycles.add_argument("--cycles-resolution", type=int, default=128, help="Cycles px across the footprint")
    cycles.add_argument("--cycles-samples", type=int, default=16, help="Cycles samples per pixel")
    cycles.add_argument(
        "--max-points",
        type=int,
        default=0,
        help="fit at most this many points, binning consecutive exposures (default 0: all 600)",
    )
    cycles.add_argument("--until-converged", action="store_true", help="sample until converged (--steps caps it)")
    cycles.add_argument(
        "--time-limit-s", type=float, default=0.0, help="stop each fit after this (its search included)"
    )
    cycles.add_argument("--seed", type=int, default=0, help="seeds the truths, noise and Cycles")
    cycles.add_argument(
        "--correlation-time-s",
        type=float,
        default=0.0,
        help="fit a correlated model error over this time too (its RMS free; default 0: none)",
    )
    cycles.add_argument(
        "--flux-error",
        action="store_true",
        help="fit the model's error in flux too (a fraction of its brightest sample, free; default: none)",
    )
    cycles.add_argument("--passes", type=int, nargs="+", help="fit and report only these passes (indices)")
    cycles.add_argument(
        "--cache-accuracy-mag",
        type=float,
        default=0.0,
        help="the fit's cached renderer: accuracy asked of its tables (default 0: the fit's own, 0.01 mag)",
    )
    cycles.add_argument(
        "--cache-grid-size",
        type=int,
        default=0,
        help="the fit's cached renderer: cube-map size (default 0: chosen from the fit's planned work)",
    )
    cycles.add_argument(
        "--cache-element-size-m",
        type=float,
        default=0.0,
        help="the fit's cached renderer: largest element (default 0: its own, the mesh radius / 30)",
    )
    cycles.add_argument(
        "--cache-normal-bins",
        type=float,
        default=0.0,
        help="the fit's cached renderer: shading classes per normal step (default 0: its own, 3)",
    )
    return parser


def main(argv=None) -> int:
    args = command_line().parse_args(argv)
    if args.cycles:
        return run_cycles(args, argv)

    from ingest import read_file
    from rsodb.fit.config import FitConfig
    from rsodb.fit.coverage import coverage_bounds, coverage_study, coverage_table, window

    observed = read_file(TOPEX_PHV)[0]
    # Fewer samples by binning consecutive exposures into longer ones, never a stride.
    template = window(observed, 0.0, 30.0, bin_size=max(1, round(150 / args.samples)))
    config = FitConfig.from_dict(
        config_record(
            args.shape, args.steps, args.walkers, args.init, args.moves, args.search_popsize, args.search_maxiter
        )
    )
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as scratch:
        recoveries = coverage_study(
            template, config, range(args.truths), noise_mag=0.02, chain_dir=scratch, processes=args.processes
        )
    elapsed = time.perf_counter() - started
    table = coverage_table(recoveries)
    if args.save:
        import dataclasses
        import json

        Path(args.save).write_text(json.dumps([dataclasses.asdict(r) for r in recoveries], indent=1))
    converged = sum(r.converged for r in recoveries)
    low, high = coverage_bounds(args.truths)
    pooled = float(np.mean([v for r in recoveries for v in r.covered.values()]))
    pooled_low, pooled_high = coverage_bounds(args.truths * len(table))
    lines = []
    for name, fraction in table.items():
        verdict = "ok" if BAND[0] <= fraction <= BAND[1] else "OUTSIDE 50-85%"
        lines.append(f"| {name} | {fraction:.2f} | {verdict} |")
        print(f"{name:24s} coverage {fraction:.2f}  {verdict}")
    print(
        f"pooled {pooled:.2f} over {args.truths * len(table)} intervals; converged chains {converged}/{args.truths}; "
        f"{elapsed:.0f} s"
    )
    for seed, r in enumerate(recoveries):
        missed = [n for n, c in r.covered.items() if not c]
        print(
            f"truth {seed:2d}: {r.autocorr_lengths:.0f} autocorrelation times, "
            f"{'converged' if r.converged else 'not converged'}, {r.elapsed_s:.0f} s; missed {missed or 'none'}"
        )
    if args.no_record:
        return 0
    coverage_figure(recoveries, FIGURE)
    print(f"wrote {FIGURE}")
    truth_rows = "\n".join(
        f"| {seed} | {r.autocorr_lengths:.0f} | " + " | ".join(f"{q:.2f}" for q in r.quantile.values()) + " |"
        for seed, r in enumerate(recoveries)
    )
    load = os.getloadavg()
    section = f"""
## Fit coverage by injection-recovery ({today()}, bench/fit_coverage.py)

{args.truths} truths drawn from the fit's prior (spin period uniform 9.76-9.96 s, phases uniform,
precession period 200-3000 s, cone angle 0-90 deg, jitter 0-0.03 mag), rendered with the
**{args.shape}** model and fitted with the same model and renderer on {len(template)} samples of 30 s
of the real TOPEX pass geometry; quoted error 0.02 mag; {args.walkers} walkers x {args.steps} steps (half
kept), walkers started by `{args.init}` (differential evolution, population {args.search_popsize} x 6, {args.search_maxiter}
generations), `{args.moves}` moves, 1 exposure sub-sample in both. Coverage = fraction of truths inside the 16-84% interval; the
project asks 50-85%; binomial 3-sigma band for {args.truths} truths: {low:.2f}-{high:.2f} (pooled over
{args.truths * len(table)} intervals: {pooled_low:.2f}-{pooled_high:.2f}, ignoring correlations within a truth).
{converged} of {args.truths} chains met the convergence criterion. {elapsed / 60:.0f} min on {os.cpu_count()} cores,
load average {load[0]:.1f} at the end.

| parameter | coverage | |
|---|---|---|
{chr(10).join(lines)}
| all (pooled) | {pooled:.2f} | |

![truth's posterior quantile per parameter](img/fit_coverage.png)

Per truth: kept chain length in autocorrelation times, and each parameter's truth quantile
({", ".join(table)}):

| truth | tau lengths | {" | ".join(table)} |
|---|---|{"---|" * len(table)}
{truth_rows}
"""
    inside = sum(BAND[0] <= fraction <= BAND[1] for fraction in table.values())
    figures = [
        figure(
            "pooled coverage of the 16-84% intervals",
            f"{pooled:.2f} over {args.truths * len(table)} intervals",
            f"{BAND[0]:.2f}-{BAND[1]:.2f}",
        ),
        figure("parameters inside 50-85%", f"{inside} of {len(table)}", f"{len(table)} of {len(table)}"),
        figure("chains converged", f"{converged} of {args.truths}"),
        figure(f"wall time, {args.truths} truths", f"{elapsed / 60:.0f} min on {os.cpu_count()} cores"),
    ]
    record("fit_coverage", command("fit_coverage.py", argv), figures, section)
    return 0


if __name__ == "__main__":
    sys.exit(main())
