"""Verdict calibration of the period search: how often each verdict is right, and where it is issued.

    python bench/verdict_calibration.py                  # ~2600 passes, 2 processes; recorded
    python bench/verdict_calibration.py --seeds 1 --no-cycles --no-record --out /tmp/verdicts.png

Injected passes whose truth is known independently of the search:

* **periodic, analytic** (`rsodb.periods.injection.shape_mag`: sinusoid, two-faced, four-faced,
  glint; exposure-integrated, a 0.5 mag pass trend, white noise): 1.5 to 150 cycles in the pass,
  S/N per sample (peak-to-peak amplitude over the noise) 0.3 to 30, four samplings: 0.2 s
  regular (1500 samples), 1 s regular (600, photometer-like), 0.2 s with 30% of the pass in two
  gaps, and two 100 s stretches 10 minutes apart;
* **periodic, rendered** by the project's direct renderer: the code-built COSMOS 2502
  (`raycast.models.cosmos2502`) spinning about a body axis (`raycast.geometry.InertialSpin`, or
  `PrecessingSpin` on a slow cone) along a real pass of COSMOS 2502 over Derenivka, 0.02-0.1 mag
  noise; and **rendered by Blender Cycles** (`raycast.cycles`, the paper's own COSMOS 2502 mesh,
  64 px, 16 samples per pixel: a few passes, Cycles is slow on two cores);
* **pure noise**: white noise on the pass trend, every sampling;
* **single glint**: a flat curve with one flash (0.2-2 s wide, 5-50 noise sigma);
* **tumbling**: torque-free rotation (`raycast.geometry.TorqueFree`, random inertia and spin)
  rendered like the periodic passes.

The truth of a rendered pass comes from its geometry: the times the Sun, the observer and their
bisector take to turn once about the spin axis in the body frame (the light curve's period lies
among them); a period P/k is also right when the noiseless curve repeats at P/k as well as at P
within the noise (parts alike: no photometric method can tell). A verdict is *right* when its
claim is true:

* "confident", "ambiguous harmonic": the reported period is within the spin-period prior a fit
  would take from it (+-1% or +-3 sigma, whichever is wider) of a right period (for a tumbler:
  the noiseless curve repeats at it to 20% of its variation);
* "aliased": the truth is periodic and the reported period is right, or the sampling admits
  aliases (two stretches, fewer than 3 samples per cycle);
* "too short": the truth repeats fewer than 3 times in the pass, or never (tumbling);
* "no signal": pure noise, or a signal out of reach (its chi-square below what white noise
  reaches somewhere on the frequency grid with probability 1e-3);
* "single glint": one flash in the pass (a single-glint injection, or a glint curve with one
  flash inside the pass);
* "non-periodic": tumbling, or a rendered curve that does not repeat at its own period (to 20%).

Chart docs/img/period_verdicts.png: (a)-(c) which verdict is issued against cycles in the pass,
S/N and sampling (analytic periodic passes); (d) truth class against verdict; (e) how often each
verdict is right, with 95% intervals. Recorded by bench/record.py.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import math
from pathlib import Path
import sys
import time

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.record import command, figure, record, today  # noqa: E402

OUTPUT = ROOT / "docs" / "img" / "period_verdicts.png"
CYCLES = (1.5, 2.0, 2.5, 3.0, 4.0, 6.0, 10.0, 25.0, 60.0, 150.0)
SNR = (0.3, 1.0, 3.0, 10.0, 30.0)
SAMPLINGS = ("0.2 s", "1 s", "0.2 s, 30% gaps", "two stretches")
SHAPES = ("sinusoid", "two_faced", "four_faced", "glint")
VERDICT_COLOURS = {
    "confident": "C0",
    "ambiguous harmonic": "C1",
    "aliased": "C4",
    "non-periodic": "C5",
    "single glint": "C6",
    "too short": "0.55",
    "no signal": "0.8",
}
# A period is right within this fraction (the +-1% prior a fit would start from).
TOLERANCE = 0.01
# A noiseless curve "repeats" at a lag when it differs from itself by at most this share of its
# variation (RMS of the difference over sqrt(2) times its standard deviation).
REPEATS = 0.2
COSMOS_PASS_START = np.datetime64("2024-01-18T15:43:43", "ns")


@dataclass(frozen=True)
class Case:
    """One injected pass: its light curve and its truth."""

    kind: str  # "periodic", "noise", "single glint", "tumbling"
    source: str  # "analytic", "renderer", "cycles"
    t_s: np.ndarray
    mag: np.ndarray
    noise_mag: float
    sampling: str
    cycles: float  # of the (first) true period in the pass; NaN without one
    snr: float  # peak-to-peak over noise per sample; NaN without a signal
    right_periods: tuple  # ((low, high), ...) intervals of right periods, seconds
    aliases_possible: bool
    noiseless: np.ndarray | None = None  # rendered curves: to test "repeats at P"
    cadence_s: float = 0.2
    signal_chi2: float = math.nan  # sum of (noiseless signal - its mean)^2 / noise^2
    flashes: int = -1  # glint shapes: flashes inside the pass


# -- sampling and analytic curves -------------------------------------------------------------
def sample_times(sampling: str, rng) -> tuple[np.ndarray, float]:
    """Sample times (s) and cadence of a sampling scheme."""
    if sampling == "0.2 s":
        return np.arange(1500) * 0.2, 0.2
    if sampling == "1 s":
        return np.arange(600) * 1.0, 1.0
    if sampling == "0.2 s, 30% gaps":
        n = 2143  # 1500 kept
        keep = np.ones(n, bool)
        gap, half = int(0.15 * n), n // 2
        for lo in (1, half):
            start = lo + int(rng.integers(0, half - gap - 1))
            keep[start : start + gap] = False
        return np.arange(n)[keep] * 0.2, 0.2
    if sampling == "two stretches":
        return np.concatenate([np.arange(500) * 0.2, 700.0 + np.arange(500) * 0.2]), 0.2
    raise ValueError(sampling)


def periodic_part(shape: str, t_s, period_s: float, amplitude: float, exposure_s: float, phase0: float, asymmetry):
    from rsodb.periods.injection import shape_mag

    offsets = exposure_s * ((np.arange(16) + 0.5) / 16 - 0.5)
    phase = (np.asarray(t_s)[:, None] + offsets[None, :]) / period_s + phase0
    mag = amplitude * shape_mag(shape, phase, asymmetry)
    return -2.5 * np.log10(np.mean(10 ** (-0.4 * mag), axis=1))


def pass_trend(t_s) -> np.ndarray:
    x = (t_s - t_s[0]) / (t_s[-1] - t_s[0]) - 0.5
    return 0.5 * (4 * x * x - 1 / 3) + 0.15 * x


def alike_parts(curve: np.ndarray, t_s: np.ndarray, period_s: float, noise_mag: float) -> list[int]:
    """k in 2..4 for which the curve repeats at P/k as well as at P, within the noise."""

    def mismatch(lag):
        shifted = np.interp(t_s + lag, t_s, curve, right=np.nan)
        ok = np.isfinite(shifted)
        return float(np.sqrt(np.mean((curve[ok] - shifted[ok]) ** 2))) if ok.sum() > 10 else math.inf

    base = mismatch(period_s)
    return [k for k in (2, 3, 4) if mismatch(period_s / k) <= base + noise_mag]


def analytic_cases(seeds: int, rng) -> list[Case]:
    cases = []
    for shape in SHAPES:
        for sampling in SAMPLINGS:
            for cycles in CYCLES:
                for snr in SNR:
                    for _ in range(seeds):
                        t, cadence = sample_times(sampling, rng)
                        span = t[-1] - t[0]
                        period = span / cycles * rng.uniform(0.97, 1.03)
                        if period < 2.5 * cadence:
                            continue
                        noise = float(rng.choice([0.02, 0.05, 0.1]))
                        asymmetry = float(rng.uniform(0.05, 0.5))
                        phase0 = rng.random()
                        curve = periodic_part(shape, t, period, snr * noise, cadence, phase0, asymmetry)
                        dense = np.arange(t[0], t[-1], cadence / 4)
                        fine = periodic_part(shape, dense, period, snr * noise, cadence, 0.0, asymmetry)
                        right = [(period * (1 - TOLERANCE), period * (1 + TOLERANCE))]
                        right += [
                            (period / k * (1 - TOLERANCE), period / k * (1 + TOLERANCE))
                            for k in alike_parts(fine, dense, period, noise)
                        ]
                        mag = 6.0 + curve + pass_trend(t) + rng.normal(0, noise, t.size)
                        # Flash centres (phase 0 of the glint shape) inside the pass.
                        first = math.ceil(t[0] / period + phase0)
                        flashes = int(math.floor(t[-1] / period + phase0) - first + 1) if shape == "glint" else -1
                        cases.append(
                            Case(
                                "periodic",
                                "analytic",
                                t,
                                mag,
                                noise,
                                sampling,
                                span / period,
                                snr,
                                tuple(right),
                                sampling == "two stretches" or period / cadence < 3,
                                cadence_s=cadence,
                                signal_chi2=float(np.sum((curve - curve.mean()) ** 2) / noise**2),
                                flashes=flashes,
                            )
                        )
    return cases


def noise_cases(count: int, rng) -> list[Case]:
    cases = []
    for i in range(count):
        sampling = SAMPLINGS[i % len(SAMPLINGS)]
        t, cadence = sample_times(sampling, rng)
        noise = float(rng.choice([0.01, 0.03, 0.1, 0.3]))
        mag = 6.0 + pass_trend(t) + rng.normal(0, noise, t.size)
        cases.append(
            Case("noise", "analytic", t, mag, noise, sampling, math.nan, math.nan, (), False, cadence_s=cadence)
        )
    return cases


def glint_cases(count: int, rng) -> list[Case]:
    cases = []
    for i in range(count):
        sampling = SAMPLINGS[i % 3]  # a flash in a gap would not be seen
        t, cadence = sample_times(sampling, rng)
        noise = float(rng.choice([0.02, 0.05, 0.1]))
        width = float(rng.uniform(0.2, 2.0))
        centre = float(rng.uniform(t[0] + 0.1 * (t[-1] - t[0]), t[-1] - 0.1 * (t[-1] - t[0])))
        centre = float(t[np.argmin(np.abs(t - centre))])  # on a sample: the flash is seen
        height = float(rng.uniform(5, 50)) * noise
        flash = -height * np.exp(-0.5 * ((t - centre) / (0.5 * width)) ** 2)
        mag = 6.0 + pass_trend(t) + flash + rng.normal(0, noise, t.size)
        cases.append(
            Case(
                "single glint",
                "analytic",
                t,
                mag,
                noise,
                sampling,
                math.nan,
                height / noise,
                (),
                False,
                cadence_s=cadence,
            )
        )
    return cases


# -- rendered curves --------------------------------------------------------------------------
def _geometry(duration_s: float, cadence_s: float):
    from ingest.site import DERENIVKA
    from raycast.geometry.orbit import Satellite
    from raycast.geometry.pass_geometry import PassGeometry
    from rsodb.samples.generate import TLES

    n = int(round(duration_s / cadence_s))
    times = COSMOS_PASS_START + (np.arange(n) * cadence_s * 1e9).astype("timedelta64[ns]")
    return PassGeometry.compute(Satellite.from_tle(list(TLES[40358])), DERENIVKA, times, 0.0, n_sub=1)


def synodic_periods_s(body, t_s, axis: int) -> list[float]:
    """Periods of the Sun, observer and bisector turning about body axis `axis` (see the module notes)."""
    a, b = [i for i in range(3) if i != axis]
    out = []
    for vector in (body.sun_body[:, 0], body.obs_body[:, 0], body.sun_body[:, 0] + body.obs_body[:, 0]):
        angle = np.unwrap(np.arctan2(vector[:, b], vector[:, a]))
        out.append(float(2 * np.pi / abs(np.polyfit(t_s, angle, 1)[0])))
    return out


def render_task(task: dict) -> dict:
    """Worker: render one attitude along the COSMOS 2502 pass (direct renderer or Cycles)."""
    from raycast.geometry.attitude import InertialSpin, PrecessingSpin, TorqueFree
    from raycast.renderer.photometry import REFERENCE_RANGE_KM, magnitude

    geometry = _geometry(task["duration_s"], 0.2)
    if task["attitude"] == "inertial":
        attitude = InertialSpin(task["ra"], task["dec"], task["period_s"], task["phase"], task["axis"])
    elif task["attitude"] == "precessing":
        attitude = PrecessingSpin(
            period_s=task["period_s"],
            phase_deg=task["phase"],
            precession_period_s=task["precession_s"],
            precession_angle_deg=task["cone_deg"],
            spin_axis=task["axis"],
        )
    else:
        attitude = TorqueFree.from_angular_momentum(task["inertia"], task["omega"], task["ra"], task["dec"])
    body = geometry.body_frame(attitude)
    start = time.process_time()
    if task["renderer"] == "cycles":
        from raycast.cycles import CyclesMesh, CyclesSettings, render_cycles

        models = ROOT.parent / "shared" / "data" / "models"
        mesh = CyclesMesh.from_obj(models / "cosmos2502_lotos.obj", models / "cosmos2502_lotos.materials.json")
        settings = CyclesSettings(samples=16, resolution=64, seed=task["seed"])
        intensity = render_cycles(
            mesh, body.sun_body[:, 0], body.obs_body[:, 0], settings, progress=False
        ).intensity_m2_sr
    else:
        from raycast.models import cosmos2502
        from raycast.renderer.methods import render

        intensity = render(cosmos2502.build(), body, method="direct", accuracy_mag=0.05).intensity_m2_sr
    with np.errstate(divide="ignore"):
        mag = magnitude(intensity, REFERENCE_RANGE_KM, "V")
    axis = {"x": 0, "y": 1, "z": 2}[task["axis"]] if task["attitude"] != "tumbling" else 0
    periods = synodic_periods_s(body, geometry.t_s, axis) if task["attitude"] != "tumbling" else []
    return {**task, "t_s": geometry.t_s, "mag": mag, "periods": periods, "cpu_s": time.process_time() - start}


def render_tasks(count: int, tumblers: int, cycles_count: int, rng) -> list[dict]:
    tasks = []
    for i in range(count):
        attitude = "inertial" if i % 2 == 0 else "precessing"
        tasks.append(
            {
                "renderer": "direct",
                "attitude": attitude,
                "period_s": float(np.exp(rng.uniform(np.log(4.0), np.log(90.0)))),
                "phase": float(rng.uniform(0, 360)),
                "axis": str(rng.choice(["x", "y", "z"])),
                "ra": float(rng.uniform(0, 360)),
                "dec": float(rng.uniform(-70, 70)),
                "precession_s": float(rng.uniform(1500, 5000)),
                "cone_deg": float(rng.uniform(5, 45)),
                "duration_s": float(rng.choice([120.0, 240.0, 400.0])),
                "seed": i,
            }
        )
    for i in range(tumblers):
        b = rng.uniform(0.6, 0.95)
        omega = rng.normal(size=3)
        omega = omega / np.linalg.norm(omega) * 2 * np.pi / rng.uniform(15, 60)
        tasks.append(
            {
                "renderer": "direct",
                "attitude": "tumbling",
                "inertia": (1.0, float(b), float(rng.uniform(1.02 - b, b))),
                "omega": tuple(float(w) for w in omega),
                "ra": float(rng.uniform(0, 360)),
                "dec": float(rng.uniform(-60, 60)),
                "axis": "x",
                "duration_s": 400.0,
                "seed": 1000 + i,
            }
        )
    for i in range(cycles_count):
        tasks.append(
            {
                "renderer": "cycles",
                "attitude": "inertial",
                "period_s": float(rng.uniform(8.0, 30.0)),
                "phase": float(rng.uniform(0, 360)),
                "axis": "x",
                "ra": float(rng.uniform(0, 360)),
                "dec": float(rng.uniform(-70, 70)),
                "duration_s": 120.0,
                "seed": 2000 + i,
            }
        )
    return tasks


def repeats(curve: np.ndarray, t_s: np.ndarray, lag: float) -> bool:
    """True when the noiseless curve differs from itself at `lag` by at most `REPEATS` of its variation."""
    shifted = np.interp(t_s + lag, t_s, curve, right=np.nan)
    ok = np.isfinite(shifted)
    if ok.sum() < 10:
        return False
    spread = np.std(curve - np.polyval(np.polyfit(t_s, curve, 1), t_s))
    return float(np.sqrt(np.mean((curve[ok] - shifted[ok]) ** 2))) <= REPEATS * math.sqrt(2) * spread


def rendered_cases(rendered: list[dict], rng) -> list[Case]:
    cases = []
    for item in rendered:
        lit = np.isfinite(item["mag"])
        t, curve = item["t_s"][lit], item["mag"][lit]
        if lit.sum() < 100:
            continue
        source = "cycles" if item["renderer"] == "cycles" else "renderer"
        for noise in (0.02, 0.05, 0.1):
            mag = curve + rng.normal(0, noise, curve.size)
            span = t[-1] - t[0]
            if item["attitude"] == "tumbling":
                cases.append(
                    Case("tumbling", source, t, mag, noise, "0.2 s", math.nan, np.ptp(curve) / noise, (), False, curve)
                )
                continue
            low, high = min(item["periods"]), max(item["periods"])
            right = [(low * (1 - TOLERANCE), high * (1 + TOLERANCE))]
            right += [
                (low / k * (1 - TOLERANCE), high / k * (1 + TOLERANCE))
                for k in alike_parts(curve, t, 0.5 * (low + high), noise)
            ]
            cases.append(
                Case(
                    "periodic",
                    source,
                    t,
                    mag,
                    noise,
                    "0.2 s",
                    span / high,
                    np.ptp(curve) / noise,
                    tuple(right),
                    False,
                    curve,
                )
            )
    return cases


# -- judging --------------------------------------------------------------------------------
def analyse(case: Case) -> dict:
    """Worker: the verdict on one case and whether it is right."""
    from rsodb.periods.lightcurve import LightCurve
    from rsodb.periods.search import find_period

    lc = LightCurve.from_arrays(case.t_s, case.mag, np.full(case.t_s.size, case.noise_mag))
    result = find_period(lc)
    found, sigma = result.best_period_s, result.uncertainty_s
    # Right within the spin-period prior a fit would start from: +-1%, or +-3 sigma if wider.
    in_right = math.isfinite(found) and any(
        lo - max(0.0, 3 * sigma - TOLERANCE * found) <= found <= hi + max(0.0, 3 * sigma - TOLERANCE * found)
        for lo, hi in case.right_periods
    )
    verdict = result.verdict
    if case.kind == "tumbling":
        periodic_truth = (
            case.noiseless is not None and math.isfinite(found) and repeats(case.noiseless, case.t_s, found)
        )
        right = {
            "confident": periodic_truth,
            "ambiguous harmonic": periodic_truth,
            "non-periodic": True,
            "too short": True,
        }.get(verdict, False)
    elif case.kind == "periodic":
        repeating = case.noiseless is None or repeats(
            case.noiseless, case.t_s, 0.5 * (case.right_periods[0][0] + case.right_periods[0][1])
        )
        # A signal is out of reach when white noise alone beats its chi-square somewhere on the
        # grid with the false-alarm threshold's probability: -2 ln(1e-3 / M), M ~ n / 2
        # independent frequencies.
        detectable = not case.signal_chi2 < -2 * math.log(1e-3 / max(case.t_s.size / 2, 1))
        right = {
            "confident": in_right,
            "ambiguous harmonic": in_right,
            "aliased": in_right or case.aliases_possible,
            "too short": case.cycles < 3.0,
            "non-periodic": not repeating,
            "no signal": not detectable,
            "single glint": case.flashes == 1,
        }.get(verdict, False)
    elif case.kind == "noise":
        right = verdict == "no signal"
    else:  # single glint
        right = verdict == "single glint"
    return {
        "kind": case.kind,
        "source": case.source,
        "sampling": case.sampling,
        "cycles": case.cycles,
        "snr": case.snr,
        "noise_mag": case.noise_mag,
        "verdict": verdict,
        "found_s": found,
        "right": bool(right),
    }


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95% Wilson score interval of a proportion k / n."""
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def chart(table, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rsodb.periods.verdicts import VERDICTS

    periodic = table[(table.kind == "periodic") & (table.source == "analytic")]
    fig = plt.figure(figsize=(13, 9))
    grid = fig.add_gridspec(2, 3)

    def stacked(ax, column, values, label, log=False):
        groups = periodic.groupby(column).verdict.value_counts(normalize=True).unstack(fill_value=0.0)
        groups = groups.reindex(values).fillna(0.0)
        x = np.arange(len(values))
        bottom = np.zeros(len(values))
        for verdict in VERDICTS:
            share = groups[verdict].to_numpy() if verdict in groups else np.zeros(len(values))
            ax.bar(x, 100 * share, bottom=100 * bottom, color=VERDICT_COLOURS[verdict], label=verdict, width=0.85)
            bottom += share
        ax.set_xticks(x, [f"{v:g}" if isinstance(v, float) else v for v in values], fontsize="small")
        ax.set(xlabel=label, ylabel="% of periodic passes", ylim=(0, 100))

    stacked(fig.add_subplot(grid[0, 0]), "cycles_bin", list(CYCLES), "cycles of the true period in the pass")
    ax = fig.axes[-1]
    ax.set_title("(a) verdict against cycles covered", fontsize="medium")
    ax.legend(fontsize="x-small", loc="lower right", framealpha=0.9)
    stacked(fig.add_subplot(grid[0, 1]), "snr", list(SNR), "S/N per sample (peak-to-peak / noise)")
    fig.axes[-1].set_title("(b) against S/N", fontsize="medium")
    stacked(fig.add_subplot(grid[0, 2]), "sampling", list(SAMPLINGS), "sampling")
    fig.axes[-1].set_title("(c) against sampling", fontsize="medium")
    fig.axes[-1].tick_params(axis="x", labelrotation=15)

    ax = fig.add_subplot(grid[1, 0:2])
    kinds = ["periodic", "noise", "single glint", "tumbling"]
    matrix = np.array([[((table.kind == k) & (table.verdict == v)).sum() for v in VERDICTS] for k in kinds])
    share = matrix / np.maximum(matrix.sum(axis=1, keepdims=True), 1)
    ax.imshow(share, cmap="Blues", vmin=0, vmax=1, aspect="auto")
    for i in range(len(kinds)):
        for j in range(len(VERDICTS)):
            if matrix[i, j]:
                ax.text(
                    j,
                    i,
                    f"{matrix[i, j]}",
                    ha="center",
                    va="center",
                    fontsize="small",
                    color="white" if share[i, j] > 0.6 else "black",
                )
    ax.set_xticks(range(len(VERDICTS)), VERDICTS, fontsize="small")
    ax.set_yticks(range(len(kinds)), [f"{k} ({(table.kind == k).sum()})" for k in kinds], fontsize="small")
    ax.set_title("(d) truth (rows) against verdict (columns): number of passes", fontsize="medium")

    ax = fig.add_subplot(grid[1, 2])
    rates = []
    for verdict in VERDICTS:
        issued = table[table.verdict == verdict]
        k, n = int(issued.right.sum()), len(issued)
        low, high = wilson(k, n)
        rates.append((verdict, k / n if n else math.nan, low, high, n))
    y = np.arange(len(rates))
    values = np.array([r[1] for r in rates]) * 100
    ax.barh(y, values, color=[VERDICT_COLOURS[r[0]] for r in rates])
    ax.errorbar(
        values,
        y,
        xerr=[values - 100 * np.array([r[2] for r in rates]), 100 * np.array([r[3] for r in rates]) - values],
        fmt="none",
        color="k",
        capsize=3,
    )
    ax.axvline(99, color="C3", lw=0.8, ls="--")
    ax.set_yticks(y, [f"{r[0]} (n={r[4]})" for r in rates], fontsize="small")
    ax.set(xlim=(0, 102), xlabel="% right (95% interval)")
    ax.set_title("(e) how often each verdict is right", fontsize="medium")
    fig.suptitle(f"Verdict calibration of the period search: {len(table)} injected passes", fontsize="medium")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=2, help="repeats of each analytic grid point")
    parser.add_argument("--renders", type=int, default=24, help="passes rendered by the direct renderer")
    parser.add_argument("--tumblers", type=int, default=16, help="torque-free tumblers rendered")
    parser.add_argument("--cycles-passes", type=int, default=3, help="passes rendered by Blender Cycles")
    parser.add_argument("--no-cycles", action="store_true", help="no Cycles renders")
    parser.add_argument("--processes", type=int, default=None)
    parser.add_argument("--out", type=Path, default=OUTPUT)
    parser.add_argument("--no-record", action="store_true", help="draw the chart only; record nothing")
    args = parser.parse_args(argv)

    import pandas as pd

    from rsodb.pool import imap_in_pool

    rng = np.random.default_rng(2018)
    start = time.perf_counter()
    tasks = render_tasks(args.renders, args.tumblers, 0 if args.no_cycles else args.cycles_passes, rng)
    direct = [t for t in tasks if t["renderer"] == "direct"]
    cycles = [t for t in tasks if t["renderer"] == "cycles"]
    rendered = list(imap_in_pool(render_task, direct, processes=args.processes, progress=True, description="renders"))
    # Cycles uses both cores itself: one pass at a time.
    rendered += [render_task(t) for t in cycles]
    render_s = time.perf_counter() - start
    cases = (
        analytic_cases(args.seeds, rng)
        + noise_cases(100 * args.seeds, rng)
        + glint_cases(50 * args.seeds, rng)
        + rendered_cases(rendered, rng)
    )
    rows = list(imap_in_pool(analyse, cases, processes=args.processes, progress=True, description="verdicts"))
    table = pd.DataFrame(rows)
    table["cycles_bin"] = [
        CYCLES[int(np.argmin(np.abs(np.log(np.array(CYCLES) / c))))] if math.isfinite(c) else math.nan
        for c in table.cycles
    ]
    total_s = time.perf_counter() - start
    chart(table, args.out)
    print(f"wrote {args.out}")

    from rsodb.periods.verdicts import VERDICTS

    lines, rates = [], {}
    for verdict in VERDICTS:
        issued = table[table.verdict == verdict]
        k, n = int(issued.right.sum()), len(issued)
        low, high = wilson(k, n)
        rates[verdict] = (k, n, low)
        lines.append(
            f"{verdict}: issued {n}, right {k}"
            + (f" ({100 * k / n:.1f}%, 95% interval {100 * low:.1f}-{100 * high:.1f}%)" if n else "")
        )
    noise = table[table.kind == "noise"]
    quiet = int((noise.verdict == "no signal").sum())
    wrong_confident = table[(table.verdict == "confident") & ~table.right]
    by_source = ", ".join(
        f"{source} {int(part.right.sum())}/{len(part)}"
        for source, part in table[table.verdict == "confident"].groupby("source")
    )
    summary = [
        f"{len(table)} passes ({', '.join(f'{k} {int((table.kind == k).sum())}' for k in ['periodic', 'noise', 'single glint', 'tumbling'])}; "
        f"rendered {int((table.source == 'renderer').sum())}, Cycles {int((table.source == 'cycles').sum())}); "
        f"{total_s:.0f} s wall ({render_s:.0f} s rendering)",
        f"'confident' right {rates['confident'][0]}/{rates['confident'][1]} "
        f"({100 * rates['confident'][0] / max(rates['confident'][1], 1):.2f}%; by source: {by_source}); target >= 99%",
        f"'no signal' on pure noise: {quiet}/{len(noise)} ({100 * quiet / max(len(noise), 1):.1f}%); target >= 99%",
        *lines,
        "confidently wrong: "
        + (
            "; ".join(
                f"{r.kind}/{r.source} {r.sampling} {r.cycles:.1f} cycles S/N {r.snr:.3g} -> {r.found_s:.4g} s"
                for r in wrong_confident.itertuples()
            )
            or "none"
        ),
        "wrong, by verdict and truth: "
        + "; ".join(
            f"{verdict}: " + ", ".join(f"{kind} {count}" for kind, count in part.kind.value_counts().items())
            for verdict, part in table[~table.right].groupby("verdict")
        ),
    ]
    print("\n".join(summary))
    if args.no_record:
        return 0
    chart_path = args.out.resolve()
    shown = (
        f"![verdict calibration]({chart_path.relative_to(ROOT / 'docs')})\n\n"
        if chart_path.is_relative_to(ROOT / "docs")
        else ""
    )
    section = (
        f"## Period verdict calibration ({today()}, bench/verdict_calibration.py)\n\n"
        "Injected passes of known truth (analytic shapes over four samplings; the project's renderer and "
        "Blender Cycles along a real COSMOS 2502 pass; pure noise; single glints; torque-free tumblers), "
        "each through `find_period`; a verdict is right when its claim is true (see the script and "
        "docs/periods.md).\n\n" + shown + "\n".join(f"* {line}" for line in summary)
    )
    confident_k, confident_n, confident_low = rates["confident"]
    figures = [
        figure(
            "'confident' right",
            f"{100 * confident_k / max(confident_n, 1):.2f}% of {confident_n} (95% lower bound {100 * confident_low:.1f}%)",
            ">= 99%",
        ),
        figure("'no signal' on pure noise", f"{100 * quiet / max(len(noise), 1):.1f}% of {len(noise)}", ">= 99%"),
    ]
    data = {
        "rates": {v: {"right": k, "issued": n} for v, (k, n, _) in rates.items()},
        "confusion": {
            kind: {v: int(((table.kind == kind) & (table.verdict == v)).sum()) for v in VERDICTS}
            for kind in ("periodic", "noise", "single glint", "tumbling")
        },
    }
    record("verdict_calibration", command("verdict_calibration.py", argv), figures, section, data)
    return 0


if __name__ == "__main__":
    sys.exit(main())
