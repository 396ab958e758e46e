"""How far a free convex body gets on a real pass: a bound on what any convex model can fit.

A convex body of many flat facets (normals spread evenly over the sphere, each with a Lambertian
term and GGX lobes of a few roughnesses, the project's own BRDFs) has a light curve linear in its
facets' reflecting areas. For a trial attitude the areas that fit best are found by non-negative
least squares on the relative flux (every sample weighted as in magnitudes), and the attitude by
differential evolution on the residual RMS in magnitudes. No facet shadows another (the body is
convex), so what this leaves is what no convex body with that attitude family can fit: the part
of the misfit that needs shadows or another attitude. With ``--holdout`` the attitude and the
areas are fitted on the first part of the pass and scored on the rest, as the model ladder does.

    python bench/convex_bound.py                          # the real TOPEX pass, inertial spin, 100 facets
    python bench/convex_bound.py --facets 50,100 --attitudes inertial,precessing,torque_free
    python bench/convex_bound.py --attitudes inertial,precessing --refit-facets 400,800,1600

Prints and records (docs/benchmarks.md) the RMS over every sample and the held-out RMS. The
search's best is a bound for its facet count only: with ``--refit-facets`` the areas of finer
spheres of facets are fitted again at the attitudes the search found (each part's own), which
shows how far more facets take the fit, and whether they predict the held-out part any better.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
import sys
import time

import numpy as np
from scipy.optimize import differential_evolution, nnls
from scipy.stats import qmc

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench.record import HISTORY, command, figure, latest, record, today  # noqa: E402

CHART = ROOT / "docs" / "img" / "convex_bound.png"
TOPEX_PHV = ROOT.parent / "shared" / "data" / "observations" / "result_22076_20240730_UT212240.phV"
# Attitude parameters searched per family, and their ranges (the spin period's is set from the
# period search: the fit's default prior of +-1% around the periodogram's period).
RANGES = {
    "inertial": {"spin_phase_deg": (0.0, 360.0), "pole_ra_deg": (0.0, 360.0), "pole_dec_deg": (-90.0, 90.0)},
    "precessing": {
        "spin_phase_deg": (0.0, 360.0),
        "precession_period_s": (50.0, 5000.0),
        "precession_phase_deg": (0.0, 360.0),
        "precession_angle_deg": (0.0, 90.0),
    },
    "torque_free": {
        "spin_phase_deg": (0.0, 360.0),
        "pole_ra_deg": (0.0, 360.0),
        "pole_dec_deg": (-90.0, 90.0),
        "inertia_ratio_2": (0.2, 5.0),
        "inertia_ratio_3": (0.2, 5.0),
        "omega_polar_deg": (0.0, 180.0),
        "omega_azimuth_deg": (0.0, 360.0),
    },
}
# Differential evolution's population: this many members per searched parameter.
POPSIZE = 12
# A sample the model misses by more than this counts as this much (a dark model sample is +inf).
CLIP_MAG = 5.0


def fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    azimuth = math.pi * (1.0 + math.sqrt(5.0)) * i
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(azimuth), r * np.sin(azimuth), z])


class ConvexBound:
    """A pass, an attitude family and a sphere of facets: the best non-negative facet areas for
    any attitude (:meth:`fit_areas`), and the residual RMS they leave (:meth:`rms`)."""

    def __init__(self, observed, attitude: str, normals: np.ndarray, roughnesses=(0.08, 0.3), ridge: float = 0.0):
        from raycast.renderer.brdf import GGX, Lambertian
        from rsodb.fit.curves import geometry_at
        from rsodb.fit.model import ATTITUDES, SpinStateModel

        self.mag = np.asarray(observed.best_mag, dtype=float)
        self.usable = np.isfinite(self.mag) & np.asarray(observed.valid, bool)
        geometry = geometry_at(observed, observed.time_utc, observed.exposure_s, 1, None)
        # The attitude's frames only: the brightness is this class's own.
        self.model = SpinStateModel(geometry, None, attitude)
        self.supports = ATTITUDES[attitude].supports
        self.geometry = geometry
        self.normals = normals
        self.brdfs = [Lambertian(1.0)] + [GGX(1.0, r) for r in roughnesses]
        self.ridge = float(ridge)

    def design(self, values) -> np.ndarray:
        """(samples, facets x BRDFs) I/E of unit areas (Earth shadow applied)."""
        body = self.geometry.body_frame(self.model.attitude_model(values))
        sun, obs = body.sun_body[:, 0], body.obs_body[:, 0]
        cos_i, cos_o = sun @ self.normals.T, obs @ self.normals.T
        cos_io = np.sum(sun * obs, axis=1)[:, None]
        seen = np.maximum(cos_o, 0.0)
        columns = [brdf.shade(cos_i, cos_o, cos_io) * seen for brdf in self.brdfs]
        return np.concatenate(columns, axis=1) * body.sunlit[:, :1]

    def fit_areas(self, design: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Non-negative areas minimising the relative flux residuals over `rows` (bool), plus
        ``ridge`` times the areas' sum of squares in units where the residuals' sum of squares of an
        all-dark model is 1 and every area weighs as the mean area of the design (ridge 0: none)."""
        reference = np.median(self.mag[rows])
        flux = 10.0 ** (-0.4 * (self.mag - reference))
        matrix, target = design[rows] / flux[rows, None], np.ones(int(rows.sum()))
        if self.ridge > 0.0:
            n, k = matrix.shape
            scale = math.sqrt(self.ridge * n / k) * float(np.sqrt(np.mean(matrix**2)))
            matrix, target = np.vstack([matrix, scale * np.eye(k)]), np.r_[target, np.zeros(k)]
        areas, _ = nnls(matrix, target, maxiter=20 * design.shape[1])
        return areas * 10.0 ** (-0.4 * reference)

    def model_mag(self, design: np.ndarray, areas: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return -2.5 * np.log10(design @ areas)

    def rms(self, values, fit_rows: np.ndarray, score_rows: np.ndarray) -> float:
        """Residual RMS (mag) over `score_rows` with the areas fitted on `fit_rows`; CLIP_MAG where
        the attitude describes no physical body (a torque-free body's moments that break the
        triangle inequality)."""
        if not self.supports(values):
            return CLIP_MAG
        design = self.design(values)
        residual = self.model_mag(design, self.fit_areas(design, fit_rows)) - self.mag
        return float(np.sqrt(np.mean(np.minimum(residual[score_rows] ** 2, CLIP_MAG**2))))


def refitted(bound: ConvexBound, found: dict, usable: np.ndarray, train=None, held=None) -> dict:
    """Whole-pass, fitted-part and held-out RMS of `bound`'s facets at attitudes another search
    found (``found``: values by part, "whole" and "train"), the areas fitted again; ``train`` and
    ``held`` (bool rows) where the pass has a held-out part."""
    row = {"whole_rms": bound.rms(found["whole"], usable, usable), "whole": found["whole"]}
    if train is not None:
        row["train_rms"] = bound.rms(found["train"], train, train)
        row["heldout_rms"] = bound.rms(found["train"], train, held)
        row["train"] = found["train"]
    return row


def search(bound: ConvexBound, names, ranges, fit_rows, seed: int, maxiter: int, start=None):
    """(best values, their RMS on `fit_rows`, evaluations) of differential evolution over the attitude.

    `start` (values by name), when given, is one member of the first generation, the others a Latin
    hypercube over the ranges: the search then ends no worse than that start. Its trials are then
    mutations of random members (``rand1bin``), not of the best (scipy's default ``best1bin``):
    from a start far better than the rest, best1bin turns the whole population to the start within
    a few generations and explores nothing else (tried: the torque-free search ended on its start)."""

    def cost(x):
        return bound.rms(dict(zip(names, x)), fit_rows, fit_rows)

    init, strategy = "latinhypercube", "best1bin"
    if start is not None:
        strategy = "rand1bin"
        low, high = np.array(ranges, dtype=float).T
        init = low + qmc.LatinHypercube(d=len(names), seed=seed).random(POPSIZE * len(names)) * (high - low)
        init[0] = [start[name] for name in names]
    found = differential_evolution(
        cost,
        ranges,
        strategy=strategy,
        popsize=POPSIZE,
        maxiter=maxiter,
        seed=seed,
        polish=False,
        tol=1e-4,
        init=init,
    )
    return dict(zip(names, found.x)), float(found.fun), int(found.nfev)


def as_torque_free(inertial) -> dict:
    """Torque-free values of the same motion as an inertial spin about body z: the angular velocity
    along z, the axis of the largest moment (a steady spin), its angular momentum at the pole."""
    same = {name: inertial[name] for name in ("spin_period_s", "spin_phase_deg", "pole_ra_deg", "pole_dec_deg")}
    return same | {"inertia_ratio_2": 1.5, "inertia_ratio_3": 2.0, "omega_polar_deg": 0.0, "omega_azimuth_deg": 0.0}


def naive_heldout_rms(observed, usable: np.ndarray, train: np.ndarray, held: np.ndarray, period_s: float) -> float:
    """The held-out RMS of no model at all: each held-out sample the training curve a whole number of
    light-curve periods earlier (rsodb.campaign.ladder.naive_forecast, the ladder's yardstick)."""
    from rsodb.campaign.ladder import naive_forecast

    mag = np.asarray(observed.best_mag, dtype=float)
    _, residuals = naive_forecast(observed.t_s[usable], mag[usable], train[usable], held[usable], period_s)
    return float(np.sqrt(np.mean(residuals**2)))


def chart(rows: list[dict], naive_mag: float | None, name: str, path: Path) -> None:
    """RMS against the number of facets per attitude family: the whole pass, the fitted part and
    the held-out part, with the issue's targets and the no-model yardstick."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure_, axis = plt.subplots(figsize=(8.0, 4.2), layout="constrained")
    # Families whose rows all repeat another's (a torque-free search that kept its inertial start)
    # share its lines and its label.
    series = {}
    for family in dict.fromkeys(r["attitude"] for r in rows):
        mine = sorted((r for r in rows if r["attitude"] == family), key=lambda r: r["facets"])
        # To a micro-magnitude: the torque-free translation of an inertial spin agrees to 1e-9, not bit for bit.
        key = tuple(
            (r["facets"], *(round(r[k], 6) if k in r else None for k in ("whole_rms", "train_rms", "heldout_rms")))
            for r in mine
        )
        series.setdefault(key, []).append(family)
    styles = {
        "whole_rms": ("-", "o", "whole pass"),
        "train_rms": (":", ".", "fitted part"),
        "heldout_rms": ("--", "s", "held out"),
    }
    for i, names in enumerate(series.values()):
        mine = sorted((r for r in rows if r["attitude"] == names[0]), key=lambda r: r["facets"])
        for key, (line, marker, label) in styles.items():
            if all(key in r for r in mine):
                axis.plot(
                    [r["facets"] for r in mine],
                    [r[key] for r in mine],
                    line,
                    marker=marker,
                    color=f"C{i}",
                    label=f"{' = '.join(names)}, {label}",
                )
    axis.axhline(0.30, color="0.3", lw=1, label="target, whole pass (0.30)")
    axis.axhline(0.35, color="0.3", lw=1, ls="--", label="target, held out (0.35)")
    if naive_mag is not None:
        axis.axhline(naive_mag, color="C3", lw=1, ls="-.", label=f"no model, held out ({naive_mag:.3f})")
    axis.set_xscale("log", base=2)
    facets = sorted({r["facets"] for r in rows})
    axis.set_xticks(facets, [str(n) for n in facets])
    axis.set_xlabel("facets (x 3 BRDFs: free reflecting areas = 3 x facets)")
    axis.set_ylabel("residual RMS (mag)")
    axis.set_ylim(bottom=0)
    axis.set_title(f"a free convex body on the pass of {name}: residual RMS against facets", fontsize=9)
    axis.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    figure_.savefig(path, dpi=110)
    plt.close(figure_)


def report(row: dict, n_brdfs: int, holdout: float) -> None:
    refit = f" (areas only, at the {row['refit_of']}-facet search's attitudes)" if "refit_of" in row else ""
    refit += f", ridge {row['ridge']:g}" if row.get("ridge") else ""
    print(
        f"{row['attitude']}, {row['facets']} facets x {n_brdfs} BRDFs{refit}: whole pass {row['whole_rms']:.3f} mag RMS"
        + (
            f"; fitted on the first {1 - holdout:.0%}: {row['train_rms']:.3f}, held out {row['heldout_rms']:.3f}"
            if "train_rms" in row
            else ""
        )
        + f" ({row['seconds']:.0f} s)",
        flush=True,
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--pass-file", type=Path, default=TOPEX_PHV, help="observation file (default: the real TOPEX pass)"
    )
    parser.add_argument("--facets", default="100", help="facet counts, joined by commas (default 100)")
    parser.add_argument(
        "--attitudes", default="inertial", help=f"attitude families, joined by commas: {', '.join(RANGES)}"
    )
    parser.add_argument(
        "--refit-facets",
        default="",
        help="finer facet counts, joined by commas, fitted again at the attitudes found with the last of --facets",
    )
    parser.add_argument(
        "--ridge",
        type=float,
        default=0.0,
        help="damping of the refitted areas (ConvexBound.fit_areas; default 0: none)",
    )
    parser.add_argument("--holdout", type=float, default=0.3, help="share of the pass held out at its end (0: none)")
    parser.add_argument("--maxiter", type=int, default=60, help="differential-evolution generations")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--no-record", action="store_true", help="print only")
    parser.add_argument("--chart-only", action="store_true", help="redraw the chart from the last recorded run")
    args = parser.parse_args(argv)
    if args.chart_only:
        last = latest("convex_bound")
        if last is None or not isinstance(last.get("data"), dict):
            raise SystemExit(f"no convex_bound run with its rows in {HISTORY}; run the benchmark first")
        chart(last["data"]["rows"], last["data"]["naive"], last["data"]["name"], CHART)
        return 0
    from ingest import read_file
    from rsodb.periods.analysis import analyse_pass

    observed = read_file(args.pass_file)[0]
    period = analyse_pass(observed, geometry=False).best_period_s
    if not math.isfinite(period):
        raise SystemExit(f"{args.pass_file}: the period search found no period to centre the spin period's range on")
    rows = []
    # Best attitudes by (family, facets, part of the pass): a torque-free search starts from the
    # inertial one (a special case of it), found first where not asked for.
    best, bounds = {}, {}

    def bound_of(attitude, n):
        if (attitude, n) not in bounds:
            bounds[attitude, n] = ConvexBound(observed, attitude, fibonacci_sphere(n))
        return bounds[attitude, n]

    def searched(attitude, n, part, rows_):
        if (attitude, n, part) not in best:
            bound = bound_of(attitude, n)
            names = ["spin_period_s", *RANGES[attitude]]
            ranges = [(0.99 * period, 1.01 * period), *RANGES[attitude].values()]
            start = as_torque_free(searched("inertial", n, part, rows_)[0]) if attitude == "torque_free" else None
            best[attitude, n, part] = search(bound, names, ranges, rows_, args.seed, args.maxiter, start)
        return best[attitude, n, part]

    cut = np.arange(len(observed)) < round((1.0 - args.holdout) * len(observed))
    counts = [int(v) for v in args.facets.split(",")]
    for attitude in args.attitudes.split(","):
        if attitude not in RANGES:
            raise SystemExit(f"--attitudes: {attitude!r} is not one of {', '.join(RANGES)}")
        for n in counts:
            bound = bound_of(attitude, n)
            parts = (bound.usable & cut, bound.usable & ~cut) if args.holdout > 0 else ()
            started = time.perf_counter()
            found = {"whole": searched(attitude, n, "whole", bound.usable)[0]}
            if parts:
                found["train"] = searched(attitude, n, "train", parts[0])[0]
            row = {"attitude": attitude, "facets": n} | refitted(bound, found, bound.usable, *parts)
            row["seconds"] = time.perf_counter() - started
            rows.append(row)
            report(row, len(bound.brdfs), args.holdout)
        for n in (int(v) for v in args.refit_facets.split(",") if v):
            started = time.perf_counter()
            finer = ConvexBound(observed, attitude, fibonacci_sphere(n), ridge=args.ridge)
            row = {"attitude": attitude, "facets": n, "refit_of": counts[-1], "ridge": args.ridge}
            # Every bound of the pass has the same usable samples, so the same parts.
            row |= refitted(finer, found, finer.usable, *parts)
            row["seconds"] = time.perf_counter() - started
            rows.append(row)
            report(row, len(finer.brdfs), args.holdout)
    naive = None
    if parts:
        naive = naive_heldout_rms(observed, bound.usable, *parts, period)
        print(f"no model (the last training cycle repeated): held out {naive:.3f} mag RMS")
    if args.no_record:
        return 0
    chart(rows, naive, observed.name, CHART)
    lines = [
        f"| {r['attitude']} | {r['facets']}{' (refit)' if 'refit_of' in r else ''}"
        + (f", ridge {r['ridge']:g}" if r.get("ridge") else "")
        + f" | {r['whole_rms']:.3f} | "
        + (f"{r['train_rms']:.3f} | {r['heldout_rms']:.3f}" if "train_rms" in r else "- | -")
        + f" | {', '.join(f'{k} {v:.4g}' for k, v in r['whole'].items())} |"
        for r in rows
    ]
    refit_text = (
        f"\nRows marked (refit): finer spheres of facets, their areas fitted again at the attitudes the {counts[-1]}-facet"
        " search found for each part (not searched again: their own best attitudes would fit them at least as well)"
        + (f", their areas damped (ridge {args.ridge:g}, ConvexBound.fit_areas)." if args.ridge else ".")
        if args.refit_facets
        else ""
    )
    section = (
        f"""
## A free convex body on a real pass ({today()}, bench/convex_bound.py)

{observed.name} ({observed.norad}), {args.pass_file.name}: {int(np.sum(bound.usable))} samples. Facet normals
spread evenly over the sphere, each with a Lambertian term and GGX lobes of roughness 0.08 and 0.3 (the
project's BRDFs), their areas non-negative and fitted by least squares on the relative flux for each trial
attitude; the attitude by differential evolution (spin period within +-1% of the period search's
{period:.4f} s). No facet shadows another, so the fit is the search's best: an upper bound on what the best
convex body of that many facets spinning this way leaves (differential evolution, {POPSIZE} x parameters x {args.maxiter} generations; the torque-free
search starts from the inertial one's best, a special case of it, and mutates random members).
Held out: the last {args.holdout:.0%} of the pass, the areas and attitude fitted on the rest.{refit_text}

| attitude | facets | RMS over every sample (mag) | fitted part (mag) | held out (mag) | whole-pass attitude |
|---|---|---|---|---|---|
"""
        + "\n".join(lines)
        + (
            f"\n\nNo model at all (each held-out sample the training curve a whole number of periods earlier, the "
            f"ladder's yardstick): held out {naive:.3f} mag RMS."
            if naive is not None
            else ""
        )
        + f"\n\n![a free convex body: RMS against facets]({CHART.relative_to(ROOT / 'docs')})\n"
    )
    figures = [
        figure(f"{r['attitude']}, {r['facets']} facets, whole pass", f"{r['whole_rms']:.3f} mag RMS") for r in rows
    ] + [
        figure(f"{r['attitude']}, {r['facets']} facets, held out", f"{r['heldout_rms']:.3f} mag RMS")
        for r in rows
        if "heldout_rms" in r
    ]
    record(
        "convex_bound",
        command("convex_bound.py", argv),
        figures,
        section,
        data={"rows": rows, "naive": naive, "name": observed.name},
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
