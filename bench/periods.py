"""Period search speed: 1000 passes of 2500 points through `find_period` on a process pool.

    python bench/periods.py                       # 1000 passes, recorded by bench/record.py
    python bench/periods.py --passes 100 --no-record

The passes are synthetic (`rsodb.periods.injection`, seeded): mixed shapes (sinusoid, two-faced,
four-faced, glint), periods log-uniform in 2-100 s (5 to 250 cycles in the 500 s pass), noise
0.02-0.2 mag, amplitudes 0.3-1.5 mag, a fifth with 20% gaps, a fifth with AR(1) red noise.
They are generated before the clock starts and sent to the workers as arrays. Measured in the
same run:

* the survey: all passes through `find_period` on a pool of one process per core (pool start
  included), wall time and the workers' CPU time; target: at most 60 s on the 2-core machine;
* one process, a sample of passes: `find_period` per pass, and the peer, astropy's one-term
  `LombScargle` on the same frequency grid (what the search starts from), for the ratio;
* how often the search recovered the injected period (within the +-1% fit prior) and how often
  it was confidently wrong.

CPU time does not depend on other jobs sharing the machine; wall time does.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import platform
import resource
import statistics
import sys
import time

# One BLAS thread, set before numpy loads OpenBLAS: the search works on small matrices, and the
# one-process timings below are CPU times, which idle BLAS threads would inflate.
for _key in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_key, "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.record import command, figure, record, today  # noqa: E402

TARGET_S = 60.0


def make_injections(n: int, seed: int = 2026):
    from rsodb.periods.injection import SHAPES, Injection

    rng = np.random.default_rng(seed)
    shapes = list(SHAPES)
    out = []
    for i in range(n):
        kind = rng.random()
        gaps = 0.2 if kind < 0.2 else 0.0
        out.append(
            Injection(
                shape=shapes[i % len(shapes)],
                period_s=float(np.exp(rng.uniform(np.log(2), np.log(100)))),
                amplitude_mag=float(rng.uniform(0.3, 1.5)),
                noise_mag=float(rng.uniform(0.02, 0.2)),
                # Gapped passes start longer so that every pass keeps 2500 points.
                n_points=int(round(2500 / (1 - gaps))),
                cadence_s=0.2,
                gap_fraction=gaps,
                red_noise_rho=0.5 if 0.2 <= kind < 0.4 else 0.0,
                asymmetry=float(rng.uniform(0.2, 0.5)),
                seed=int(seed * 1000 + i),
            )
        )
    return out


def analyse(item):
    """Worker: (injection, light curve) -> (true period, found period, verdict)."""
    from rsodb.periods.search import find_period

    injection, lc = item
    result = find_period(lc)
    return injection.period_s, result.best_period_s, result.verdict


def peer_lombscargle(lc):
    from astropy.timeseries import LombScargle

    from rsodb.periods.power import frequency_grid

    detrended = lc.detrend()
    grid = frequency_grid(detrended.t_s)
    return LombScargle(detrended.t_s, detrended.mag, detrended.mag_err).power(
        grid, method="fast", assume_regular_frequency=True
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--passes", type=int, default=1000)
    parser.add_argument("--sample", type=int, default=40, help="passes timed one by one in this process")
    parser.add_argument("--processes", type=int, default=None)
    parser.add_argument("--no-record", action="store_true", help="print only; record nothing")
    parser.add_argument("--note", default="", help="a sentence appended to the recorded section")
    args = parser.parse_args(argv)

    from rsodb.periods.injection import RECOVERY_TOLERANCE, synthetic_lightcurve
    from rsodb.periods.search import find_period
    from rsodb.pool import default_processes, imap_in_pool

    processes = args.processes or default_processes()
    injections = make_injections(args.passes)
    items = [(inj, synthetic_lightcurve(inj)) for inj in injections]
    sizes = sorted({lc.t_s.size for _, lc in items})
    print(f"{len(items)} synthetic passes of {sizes[0]}-{sizes[-1]} points; {processes} worker processes")

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    rows = list(imap_in_pool(analyse, items, processes=processes, progress=True, description="find_period"))
    survey_s = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    worker_cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)

    truth, found, verdicts = (np.array(column) for column in zip(*rows))
    error = np.abs(found - truth) / truth
    named = np.isin(verdicts, ["confident", "ambiguous harmonic"])
    recovered = float(np.mean(named & (error < RECOVERY_TOLERANCE)))
    confident_wrong = float(np.mean((verdicts == "confident") & ~(error < RECOVERY_TOLERANCE)))

    sample = items[: args.sample]
    find_period(sample[0][1])  # warm imports and caches
    per_pass, per_peer = [], []
    for _, lc in sample:
        # CPU time of this process: less sensitive than wall time to the other jobs on the machine.
        t0 = time.process_time()
        find_period(lc)
        per_pass.append(time.process_time() - t0)
        t0 = time.process_time()
        peer_lombscargle(lc)
        per_peer.append(time.process_time() - t0)
    median_ms, peer_ms = 1e3 * statistics.median(per_pass), 1e3 * statistics.median(per_peer)
    load = os.getloadavg()

    verdict_counts = {
        v: int(np.sum(verdicts == v)) for v in ("confident", "ambiguous harmonic", "too short", "no signal")
    }
    status = "met" if survey_s <= TARGET_S else "MISSED"
    lines = [
        f"survey: {len(items)} passes in {survey_s:.1f} s wall ({len(items) / survey_s:.1f} passes/s, "
        f"target <= {TARGET_S:.0f} s: {status}); workers' CPU {worker_cpu_s:.1f} s = "
        f"{1e3 * worker_cpu_s / len(items):.1f} ms per pass",
        f"one process (CPU time): find_period median {median_ms:.1f} ms per pass; astropy LombScargle (fast, same grid) "
        f"{peer_ms:.1f} ms; ratio {median_ms / peer_ms:.1f}x",
        f"recovered within +-{100 * RECOVERY_TOLERANCE:g}%: {100 * recovered:.1f}%; confidently wrong: "
        f"{100 * confident_wrong:.1f}%; verdicts {verdict_counts}",
        f"load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}",
    ]
    print("\n".join(lines))
    if not args.no_record:
        measured = {
            "passes": len(items),
            "processes": processes,
            "survey_s": survey_s,
            "worker_cpu_s": worker_cpu_s,
            "sample": len(sample),
            "find_period_cpu_ms": median_ms,
            "peer_cpu_ms": peer_ms,
            "recovered": recovered,
            "confident_wrong": confident_wrong,
            "verdicts": verdict_counts,
            "load": load,
        }
        record(
            "periods", command("periods.py", argv), headline_figures(measured), report(measured, args.note), measured
        )
    return 0


def report(m: dict, note: str = "") -> str:
    """The run's markdown section from its measurements (``m``, as main records them)."""
    n, load, processes = m["passes"], m["load"], m["processes"]
    status = "met" if m["survey_s"] <= TARGET_S else "MISSED"
    return (
        f"## Period search (bench/periods.py, {today()})\n\n"
        f"{n} synthetic passes of 2500 points (0.2 s cadence, mixed "
        f"shapes, periods 2-100 s, 20% with gaps, 20% with red noise) through `rsodb.periods.find_period`. "
        f"{os.cpu_count()} CPUs ({platform.machine()}), Python {platform.python_version()}; load average "
        f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} at the end: the machine is shared, so wall times are "
        f"upper bounds; CPU times suffer less (cache and core contention only). Two free cores would need about "
        f"{m['worker_cpu_s'] / processes:.0f} s for the survey's CPU time.\n\n"
        f"| measurement | value | ratio |\n|---|---:|---:|\n"
        f"| survey, {processes} processes, pool start included: wall | {m['survey_s']:.1f} s "
        f"| target <= {TARGET_S:.0f} s: {status} |\n"
        f"| survey: workers' CPU per pass | {1e3 * m['worker_cpu_s'] / n:.1f} ms | |\n"
        f"| one process, CPU, median of {m['sample']}: find_period | {m['find_period_cpu_ms']:.1f} ms "
        f"| {m['find_period_cpu_ms'] / m['peer_cpu_ms']:.1f}x |\n"
        f"| one process, CPU, median of {m['sample']}: astropy LombScargle alone (peer) | {m['peer_cpu_ms']:.1f} ms "
        f"| 1.0x |\n\n"
        f"Recovered within the +-1% prior: {100 * m['recovered']:.1f}%; confidently wrong: "
        f"{100 * m['confident_wrong']:.1f}%; verdicts: "
        + ", ".join(f"{v} {c}" for v, c in m["verdicts"].items())
        + ".\n"
        + (f"\n{note}\n" if note else "")
    )


def headline_figures(m: dict) -> list[dict]:
    return [
        figure(
            f"survey, {m['passes']} passes, {m['processes']} processes",
            f"{m['survey_s']:.1f} s wall",
            f"<= {TARGET_S:.0f} s",
        ),
        figure("workers' CPU per pass", f"{1e3 * m['worker_cpu_s'] / m['passes']:.1f} ms"),
        figure(
            "find_period, one process",
            f"{m['find_period_cpu_ms']:.1f} ms CPU per pass ({m['find_period_cpu_ms'] / m['peer_cpu_ms']:.1f}x astropy LombScargle)",
        ),
        figure(
            "recovered within the +-1% prior",
            f"{100 * m['recovered']:.1f}% (confidently wrong {100 * m['confident_wrong']:.1f}%)",
        ),
    ]


if __name__ == "__main__":
    sys.exit(main())
