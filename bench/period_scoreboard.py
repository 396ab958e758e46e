"""Real-data scoreboard of the period search: every pass in ../shared/data/observations, its
period and verdict, and what is known about the object independently.

    python bench/period_scoreboard.py              # prints the table, recorded by bench/record.py
    python bench/period_scoreboard.py --no-record

Every file the readers accept is read (one pass per band) and goes through `analyse_pass` with
the default settings. docs/periods.md quotes the table; tests/test_periods.py checks its values.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
import sys
import time

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.record import command, figure, record, today  # noqa: E402

OBSERVATIONS = (ROOT / ".." / "shared" / "data" / "observations").resolve()

# What is known about each object from sources other than these passes (NORAD id -> text).
KNOWN = {
    22076: (
        "10.73 s on 2016-10-19, spinning up steadily since 2006 (Kucharski et al. 2017, GRL 44); "
        "9.85 s (manual) / 9.86 +- 0.01 s (MCMC) on 2020-08-02 (the seed paper): the spin-up continues"
    ),
    44517: "no published spin period found",
    51511: (
        "no published spin period found; independent within the project: the Uzhhorod photometer "
        "(other instrument, site and band) on 2025-01-30 against the Derenivka CCD on 2025-03-11"
    ),
}


def passes(folder: Path):
    """(file name, pass) for every pass of every readable file in `folder`, sorted by name."""
    import ingest

    for path in sorted(folder.iterdir()):
        if path.name.startswith(".") or path.suffix.lower() in (".md", ".txt"):
            continue
        for pass_ in ingest.read_file(path):
            yield path.name, pass_


def period_text(result) -> str:
    if not math.isfinite(result.best_period_s):
        return "-"
    text = f"{result.best_period_s:.5g} +- {result.uncertainty_s:.2g}"
    return text if result.has_period else f"({text})"


def sidereal_text(result) -> str:
    if result.synodic is None:
        return "no TLE or OMM in the file" if "neither a TLE nor an OMM" in result.synodic_note else "-"
    return f"{result.synodic.sidereal_prograde_s:.4f} .. {result.synodic.sidereal_retrograde_s:.4f}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--observations", type=Path, default=OBSERVATIONS)
    parser.add_argument("--no-record", action="store_true", help="print the table only; record nothing")
    args = parser.parse_args(argv)

    from rsodb.periods.analysis import analyse_pass

    header = (
        "| file | object, band, date | LS peak s | period s (1 sigma) | verdict | cycles | S/N | "
        "sidereal s (pro .. retro) | known independently |\n|---|---|---:|---:|---|---:|---:|---|---|"
    )
    rows, reasons, data, seconds = [], [], [], []
    for name, pass_ in passes(args.observations):
        start = time.perf_counter()
        result = analyse_pass(pass_)
        seconds.append(time.perf_counter() - start)
        date = str(result.epoch_utc)[:10] if result.epoch_utc is not None else "-"
        rows.append(
            f"| {name} | {result.label.split(' ' + pass_.band + ' ')[0]} {pass_.band}, {date} | "
            f"{result.peak_period_s:.5g} | {period_text(result)} | {result.verdict} | {result.n_cycles:.1f} | "
            f"{result.signal_to_noise:.3g} | {sidereal_text(result)} | {KNOWN.get(result.norad, '-')} |"
        )
        reasons.append(f"* {name} {pass_.band}: {result.verdict}: {result.reason}")
        data.append(
            {
                "file": name,
                "band": pass_.band,
                "norad": result.norad,
                "period_s": result.best_period_s,
                "uncertainty_s": result.uncertainty_s,
                "verdict": result.verdict,
                "n_cycles": result.n_cycles,
                "reason": result.reason,
                "seconds": seconds[-1],
            }
        )
    table = header + "\n" + "\n".join(rows)
    reasons = "\n".join(reasons)
    print(table)
    print()
    print(reasons)
    if args.no_record:
        return 0
    section = (
        f"## Real-data period scoreboard ({today()}, bench/period_scoreboard.py)\n\n"
        f"Every pass in ../shared/data/observations through `analyse_pass` (default settings), "
        f"{sum(seconds):.0f} s in all.\n\n{table}\n\nWhy each verdict:\n\n{reasons}"
    )
    named = sum(1 for d in data if d["verdict"] in ("confident", "ambiguous harmonic"))
    figures = [figure("real passes with a period", f"{named} of {len(data)}")]
    record("period_scoreboard", command("period_scoreboard.py", argv), figures, section, data)
    return 0


if __name__ == "__main__":
    sys.exit(main())
