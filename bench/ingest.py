"""Ingest speed and memory: 2000 ccd_phot files of 2500 rows over 50 objects into a new archive.

    python bench/ingest.py                 # full size, 3 repeats, recorded by bench/record.py
    python bench/ingest.py --files 200 --repeats 1 --no-record     # a quick look

The corpus is synthesised once (`rsodb.samples.synthetic`, written by `ingest.writers` in the
real layout) into a temporary directory. Each measurement runs in a fresh Python process, so its
peak memory (``ru_maxrss`` of the process and, separately, of its reader processes) is its own
and import time is excluded. Measured, in the same run:

* ``ingest`` with the default reader pool (one process per CPU), the figure of merit;
* ``ingest, workers=0``: reading in the committing process, the peer that shows what the pool buys;
* ``parse only``: `ingest.read_file` over every file in one process, no archive: the floor that
  a single process cannot beat;
* ``re-ingest``: the same files into the filled archive, all already present (hashing only).

Target: at least 100 files/s on the project's 2-core machine.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
import json
import os
from pathlib import Path
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

# Running this file puts bench/ first on sys.path, where "ingest" would name this script rather
# than the project's package: bench/ leaves sys.path and the project's root leads it.
sys.path[:] = [entry for entry in sys.path if Path(entry or ".").resolve() != Path(__file__).resolve().parent]
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.record import command, figure, record, today  # noqa: E402

TARGET_FILES_PER_S = 100.0
SEED = 2026


def _write_piece(args) -> int:
    from rsodb.samples.synthetic import write_synthetic_corpus

    directory, n_files, n_points, n_objects, indices = args
    return len(write_synthetic_corpus(directory, n_files, n_points, n_objects, seed=SEED, indices=indices))


def make_corpus(directory: Path, n_files: int, n_points: int, n_objects: int) -> None:
    """Write the corpus in parallel pieces (file k depends only on the seed and k)."""
    workers = os.cpu_count() or 1
    step = -(-n_files // (4 * workers))
    pieces = [
        (directory, n_files, n_points, n_objects, range(i, min(i + step, n_files))) for i in range(0, n_files, step)
    ]
    with ProcessPoolExecutor(workers) as pool:
        written = sum(pool.map(_write_piece, pieces))
    assert written == n_files


def _measure(mode: str, archive: str, corpus: str, workers: int | None) -> dict:
    """Runs in a child process: one timed operation, its wall time and peak memory."""

    def cpu_s() -> float:
        own, readers = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
        return own.ru_utime + own.ru_stime + readers.ru_utime + readers.ru_stime

    if mode == "parse":
        import ingest

        paths = sorted(Path(corpus).iterdir())
        cpu_start = cpu_s()
        start = time.perf_counter()
        for path in paths:
            ingest.read_file(path)
        elapsed, n = time.perf_counter() - start, len(paths)
    else:
        from rsodb.archive import Archive

        target = Archive(archive)
        cpu_start = cpu_s()
        start = time.perf_counter()
        report = target.ingest([corpus], progress=False, workers=workers)
        elapsed = time.perf_counter() - start
        assert report.ok, report.summary()
        n = report.n_files
    return {
        "files": n,
        "elapsed_s": elapsed,
        "cpu_s": cpu_s() - cpu_start,
        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "peak_rss_readers_mib": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
    }


def measure(mode: str, archive: Path, corpus: Path, workers: int | None = None) -> dict:
    command = [sys.executable, __file__, "_measure", mode, str(archive), str(corpus), str(workers)]
    output = subprocess.run(command, check=True, capture_output=True, text=True).stdout
    return json.loads(output.splitlines()[-1])


def run(n_files: int, n_points: int, n_objects: int, repeats: int) -> dict:
    results: dict[str, list[dict]] = {"ingest": [], "ingest, workers=0": [], "parse only": [], "re-ingest": []}
    with tempfile.TemporaryDirectory(prefix="rsodb-bench-") as tmp:
        tmp = Path(tmp)
        corpus = tmp / "corpus"
        started = time.perf_counter()
        make_corpus(corpus, n_files, n_points, n_objects)
        corpus_mib = sum(path.stat().st_size for path in corpus.iterdir()) / 2**20
        print(
            f"corpus: {n_files} files, {corpus_mib:.0f} MiB, written in {time.perf_counter() - started:.0f} s",
            flush=True,
        )
        archive_mib = 0.0
        for repeat in range(repeats):
            for mode, workers in (("ingest", None), ("ingest, workers=0", 0), ("parse only", None)):
                archive = tmp / f"archive-{repeat}-{workers}"
                result = measure("parse" if mode == "parse only" else "ingest", archive, corpus, workers)
                results[mode].append(result)
                print(
                    f"  {mode:<18} {result['files'] / result['elapsed_s']:7.1f} files/s  "
                    f"peak {result['peak_rss_mib']:.0f} MiB",
                    flush=True,
                )
                if mode == "ingest":
                    archive_mib = sum(p.stat().st_size for p in (archive / "objects").glob("*.h5")) / 2**20
                    results["re-ingest"].append(measure("ingest", archive, corpus, None))
                shutil.rmtree(archive, ignore_errors=True)
    return {
        "results": results,
        "n_files": n_files,
        "n_points": n_points,
        "n_objects": n_objects,
        "repeats": repeats,
        "corpus_mib": corpus_mib,
        "archive_mib": archive_mib,
    }


def rates(results: dict) -> tuple[dict, dict]:
    """Median files/s and CPU ms per file of each operation."""
    rate = {mode: statistics.median(r["files"] / r["elapsed_s"] for r in rows) for mode, rows in results.items()}
    cpu_ms = {mode: 1e3 * statistics.median(r["cpu_s"] / r["files"] for r in rows) for mode, rows in results.items()}
    return rate, cpu_ms


def report(run_result: dict) -> str:
    results = run_result["results"]
    rate, cpu_ms = rates(results)
    memory = {mode: max(r["peak_rss_mib"] for r in rows) for mode, rows in results.items()}
    readers = {mode: max(r["peak_rss_readers_mib"] for r in rows) for mode, rows in results.items()}
    load = os.getloadavg()
    verdict = "meets" if rate["ingest"] >= TARGET_FILES_PER_S else "MISSES"
    lines = [
        f"## Archive ingest ({today()}, bench/ingest.py)",
        "",
        f"{run_result['n_files']} synthetic ccd_phot files of {run_result['n_points']} "
        f"rows over {run_result['n_objects']} objects ({run_result['corpus_mib']:.0f} MiB of text) into a new "
        f"archive ({run_result['archive_mib']:.0f} MiB of HDF5); median of {run_result['repeats']} run(s), each in a "
        f"fresh process. {os.cpu_count()} CPUs ({platform.processor() or platform.machine()}), "
        f"Python {platform.python_version()}; load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} "
        "(1/5/15 min) at the end: the machine is shared, so the rates are lower bounds.",
        "",
        "| operation | files/s | ratio to ingest | CPU ms per file (all processes) | peak RSS, MiB (largest reader process) |",
        "|---|---:|---:|---:|---:|",
    ]
    for mode in results:
        pooled = mode in ("ingest", "re-ingest")
        lines.append(
            f"| {mode} | {rate[mode]:.1f} | {rate[mode] / rate['ingest']:.2f} | {cpu_ms[mode]:.1f} | "
            f"{memory[mode]:.0f} ({f'{readers[mode]:.0f}' if pooled else '-'}) |"
        )
    lines += [
        "",
        f"Target >= {TARGET_FILES_PER_S:.0f} files/s: ingest {verdict} it at {rate['ingest']:.1f} files/s. "
        f"The reader pool runs {rate['ingest'] / rate['ingest, workers=0']:.2f}x the in-process ingest; "
        f"parsing alone in one process reaches {rate['parse only']:.1f} files/s. CPU time does not depend "
        f"on the other jobs sharing the machine: at {cpu_ms['ingest']:.1f} ms of CPU per file, two idle cores "
        f"would ingest at most {2e3 / cpu_ms['ingest']:.0f} files/s.",
        "",
    ]
    return "\n".join(lines)


def headline_figures(run_result: dict) -> list[dict]:
    rate, cpu_ms = rates(run_result["results"])
    return [
        figure(
            f"ingest, {run_result['n_files']} files of {run_result['n_points']} rows",
            f"{rate['ingest']:.1f} files/s",
            f">= {TARGET_FILES_PER_S:.0f} files/s",
        ),
        figure("re-ingest (all files present)", f"{rate['re-ingest']:.1f} files/s"),
        figure(
            "CPU per file, ingest",
            f"{cpu_ms['ingest']:.1f} ms (two idle cores: at most {2e3 / cpu_ms['ingest']:.0f} files/s)",
        ),
    ]


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "_measure":
        mode, archive, corpus, workers = argv[1:5]
        print(json.dumps(_measure(mode, archive, corpus, None if workers == "None" else int(workers))))
        return 0
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--files", type=int, default=2000)
    parser.add_argument("--rows", type=int, default=2500)
    parser.add_argument("--objects", type=int, default=50)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-record", action="store_true", help="print only; record nothing")
    args = parser.parse_args(argv)
    run_result = run(args.files, args.rows, args.objects, args.repeats)
    text = report(run_result)
    print(text)
    if not args.no_record:
        record("ingest", command("ingest.py", argv), headline_figures(run_result), text, data=run_result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
