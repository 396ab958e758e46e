"""Injection-recovery chart of the period search: docs/img/period_recovery.png.

    python bench/period_recovery.py              # ~1400 seeded synthetic passes, 2 processes; recorded
    python bench/period_recovery.py --seeds 1    # a quicker, noisier chart
    python bench/period_recovery.py --seeds 1 --no-record --out /tmp/recovery.png

Synthetic passes (`rsodb.periods.injection`): 2500 points at a 0.2 s cadence (500 s), every shape
(sinusoid, two-faced, four-faced, glint), 1.5 to 200 cycles in the pass, amplitude 0.3 or
1 mag, noise 0.05 or 0.2 mag, with and without 30% gaps and AR(1) red noise; periods get a
random +-3% so that they are not commensurate with the cadence. A pass is *recovered* when
the verdict names a period and the +-1% fit prior contains the truth.

Panels: (a) recovery rate against cycles in the pass, per shape, and how often a confident
verdict was wrong - split into P/2..P/4 of the truth (a cycle whose parts look alike within
the noise, which no photometric method resolves) and other errors;
(b) period error of the recovered passes (median and 90th percentile of |dP/P|) and the
median reported 1-sigma error; (c) recovery rate per observing condition; (d) the two-faced
curve with nearly equal halves: recovery against the asymmetry.

The run's figures are recorded by bench/record.py (docs/benchmarks/history.jsonl, docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.record import command, figure, record, today  # noqa: E402

OUTPUT = ROOT / "docs" / "img" / "period_recovery.png"
CYCLES = np.array([1.5, 2.0, 2.5, 3.0, 4.0, 6.0, 10.0, 16.0, 25.0, 40.0, 65.0, 100.0, 150.0, 200.0])
DURATION_S = 2500 * 0.2


def injections(seeds: int):
    from rsodb.periods.injection import SHAPES, Injection

    rng = np.random.default_rng(11)
    conditions = [("white", 0.0, 0.0), ("30% gaps", 0.3, 0.0), ("red noise", 0.0, 0.7)]
    out = []
    for shape in SHAPES:
        for cycles in CYCLES:
            for amplitude in (0.3, 1.0):
                for noise in (0.05, 0.2):
                    for name, gaps, rho in conditions:
                        for _ in range(seeds):
                            period = DURATION_S / cycles * rng.uniform(0.97, 1.03)
                            out.append(
                                (
                                    name,
                                    Injection(
                                        shape,
                                        float(period),
                                        amplitude,
                                        noise,
                                        gap_fraction=gaps,
                                        red_noise_rho=rho,
                                        seed=int(rng.integers(2**31)),
                                    ),
                                )
                            )
    asymmetric = [
        (
            "asymmetry",
            Injection(
                "two_faced",
                float(9.5 * rng.uniform(0.97, 1.03)),
                1.0,
                0.1,
                asymmetry=float(a),
                seed=int(rng.integers(2**31)),
            ),
        )
        for a in (0.0, 0.01, 0.02, 0.03, 0.05, 0.08, 0.12)
        for _ in range(6 * seeds)
    ]
    return out + asymmetric


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=2, help="repeats of each grid point")
    parser.add_argument("--processes", type=int, default=None)
    parser.add_argument("--out", type=Path, default=OUTPUT)
    parser.add_argument("--no-record", action="store_true", help="draw the chart only; record nothing")
    args = parser.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rsodb.periods.injection import SHAPES, recover

    cases = injections(args.seeds)
    table = recover([inj for _, inj in cases], processes=args.processes, progress=True)
    table["condition"] = [name for name, _ in cases]
    table["cycles_bin"] = np.array([CYCLES[np.argmin(np.abs(np.log(CYCLES / c)))] for c in table.n_cycles])
    grid = table[table.condition != "asymmetry"]

    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    ax = axes[0, 0]
    for i, shape in enumerate(SHAPES):
        rate = grid[grid["shape"] == shape].groupby("cycles_bin").recovered.mean()
        ax.plot(rate.index, 100 * rate.values, "o-", color=f"C{i}", label=shape, ms=4)
    wrong = grid.assign(other=grid.confident_wrong & ~grid.confident_subharmonic).groupby("cycles_bin")
    ax.plot(
        wrong.confident_subharmonic.mean().index,
        100 * wrong.confident_subharmonic.mean().values,
        "k--",
        label="confident at P/2..P/4 (parts alike\nwithin the noise; all shapes)",
    )
    ax.plot(wrong.other.mean().index, 100 * wrong.other.mean().values, "k:", label="confidently wrong otherwise")
    ax.axvline(3, color="0.5", lw=0.8, ls=":")
    ax.text(2.9, 62, "below 3 cycles:\n'too short'", fontsize="small", color="0.4", ha="right")
    ax.set(
        xscale="log",
        xlabel="cycles in the pass",
        ylabel="% of passes",
        ylim=(-3, 103),
        title="(a) recovered within the +-1% prior",
    )
    ax.legend(fontsize="small", loc="lower right", bbox_to_anchor=(1.0, 0.1))

    ax = axes[0, 1]
    ok = grid[grid.recovered]
    error = ok.assign(abs_error=ok.relative_error.abs(), sigma=ok.uncertainty_s / ok.period_s)
    by_cycles = error.groupby("cycles_bin")
    ax.plot(by_cycles.abs_error.median().index, by_cycles.abs_error.median().values, "o-", label="median |dP/P|")
    ax.plot(
        by_cycles.abs_error.quantile(0.9).index,
        by_cycles.abs_error.quantile(0.9).values,
        "s--",
        label="90th percentile |dP/P|",
    )
    ax.plot(by_cycles.sigma.median().index, by_cycles.sigma.median().values, "k:", label="median reported sigma/P")
    ax.axhline(0.01, color="C3", lw=0.8)
    ax.text(1.6, 0.012, "+-1% prior", color="C3", fontsize="small")
    ax.set(
        xscale="log",
        yscale="log",
        xlabel="cycles in the pass",
        ylabel="relative period error",
        title="(b) period error of recovered passes",
    )
    ax.legend(fontsize="small")

    ax = axes[1, 0]
    for i, (condition, part) in enumerate(grid.groupby("condition")):
        for j, (noise, sub) in enumerate(part.groupby("noise_mag")):
            rate = sub.groupby("cycles_bin").recovered.mean()
            ax.plot(
                rate.index,
                100 * rate.values,
                ["o-", "s--"][j],
                color=f"C{i}",
                ms=4,
                label=f"{condition}, noise {noise:g} mag",
            )
    ax.set(
        xscale="log",
        xlabel="cycles in the pass",
        ylabel="% recovered",
        ylim=(-3, 103),
        title="(c) by observing condition (all shapes, both amplitudes)",
    )
    ax.legend(fontsize="small", loc="lower right")

    ax = axes[1, 1]
    two = table[table.condition == "asymmetry"]
    half = np.abs(two.found_period_s / (two.period_s / 2) - 1) < 0.01
    rows = two.assign(half=half).groupby("asymmetry")
    ax.plot(rows.recovered.mean().index, 100 * rows.recovered.mean().values, "o-", label="recovered (9.5 s)")
    ax.plot(rows.half.mean().index, 100 * rows.half.mean().values, "s--", label="reported the half period")
    ax.plot(
        rows.confident_wrong.mean().index, 100 * rows.confident_wrong.mean().values, "k:", label="confidently wrong"
    )
    ax.set(
        xlabel="difference between the halves (fraction of the amplitude)",
        ylabel="% of passes",
        ylim=(-3, 103),
        title="(d) two-faced curve, 1 mag, noise 0.1 mag, 53 cycles",
    )
    ax.legend(fontsize="small")
    fig.suptitle(f"Period search injection-recovery: {len(table)} synthetic passes of 2500 points", fontsize="medium")
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")

    long_enough = grid[grid.n_cycles >= 3.5]
    other = long_enough.confident_wrong & ~long_enough.confident_subharmonic
    recovered = 100 * long_enough.recovered.mean()
    wrong, subharmonic = 100 * long_enough.confident_wrong.mean(), 100 * long_enough.confident_subharmonic.mean()
    lines = [
        f"{len(grid)} grid passes; with >= 3.5 cycles: recovered {recovered:.1f}%, "
        f"confidently wrong {wrong:.2f}% (at P/2..P/4: {subharmonic:.2f}%, otherwise {100 * other.mean():.2f}%)",
        "recovered by amplitude and noise (mag): "
        + ", ".join(
            f"{a:g} / {n:g}: {rate:.3f}"
            for (a, n), rate in grid.groupby(["amplitude_mag", "noise_mag"]).recovered.mean().items()
        ),
        "recovered by shape: "
        + ", ".join(f"{name} {rate:.3f}" for name, rate in grid.groupby("shape").recovered.mean().items()),
        "recovered by condition: "
        + ", ".join(f"{name} {rate:.3f}" for name, rate in grid.groupby("condition").recovered.mean().items()),
        "verdicts below 3 cycles: "
        + ", ".join(f"{v} {c}" for v, c in grid[grid.n_cycles < 2.9].verdict.value_counts().items()),
        "two-faced curve, recovered by asymmetry: "
        + ", ".join(f"{a:g} {rate:.2f}" for a, rate in rows.recovered.mean().items()),
    ]
    print("\n".join(lines))
    if args.no_record:
        return 0
    chart = args.out.resolve()
    shown = f"![injection-recovery]({chart.relative_to(ROOT / 'docs')})" if chart.is_relative_to(ROOT / "docs") else ""
    section = (
        f"## Period search injection-recovery ({today()}, bench/period_recovery.py)\n\n"
        f"{len(table)} seeded synthetic passes of 2500 points at a 0.2 s cadence ({args.seeds} per grid point; "
        f"see docs/periods.md), chart {chart.name}. A pass is recovered when the verdict names a period and "
        "the +-1% fit prior holds the truth.\n\n"
        + (f"{shown}\n\n" if shown else "")
        + "\n".join(f"* {line}" for line in lines)
    )
    figures = [
        figure("recovered, passes of >= 3.5 cycles", f"{recovered:.1f}% of {len(long_enough)}"),
        figure("confidently wrong, >= 3.5 cycles", f"{wrong:.2f}% ({subharmonic:.2f}% at P/2..P/4)"),
    ]
    record("period_recovery", command("period_recovery.py", argv), figures, section)
    return 0


if __name__ == "__main__":
    sys.exit(main())
