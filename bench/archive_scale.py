"""The archive at survey scale: 20,000 objects and 100,000 passes against 10 objects.

    python bench/archive_scale.py                  # full size; archives built once under --dir, reused
    python bench/archive_scale.py --objects 2000 --passes 10000 --ingest-files 500 --repeats 3 --no-record

The big archive is built by `rsodb.samples.synthetic.write_synthetic_archive` (object files
written in bulk with the archive's layout functions, then the catalog index built from them as
``rsodb check`` does), with a stored period result per pass; the small one (10 objects, the same
passes per object) the same way. Every command is timed as a whole process (start-up included),
the big and the small archive in turn, and the median of the repeats is quoted with the ratio of
medians. Measured:

* ``rsodb ls --norad N``, ``rsodb show PASS``, ``rsodb periods --object N`` (one object, its
  stored survey reported) and ``rsodb periods --object N --force`` (searched again);
* a survey query over all passes (``Archive.catalog(period_min=, period_max=, verdict=)`` in a
  process that has opened the archive, and ``rsodb ls --period-min ... --json`` as a command);
* how long ``rsodb ls`` of everything takes to print its first row, and all of them;
* ingest of a night: one new 300-row ccd_phot file for each of ``--ingest-files`` objects, into
  the big archive and, as the peer, into an empty one.

Targets (issue 17): ingest >= 150 files/s; the one-object commands <= 0.5 s and <= 1.5x the
10-object archive; the survey query <= 1 s; the first row of ``rsodb ls`` <= 1 s.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path[:] = [entry for entry in sys.path if Path(entry or ".").resolve() != Path(__file__).resolve().parent]
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.record import command, figure, record, today  # noqa: E402

TARGETS = {"ingest_files_per_s": 150.0, "one_object_s": 0.5, "ratio": 1.5, "survey_s": 1.0, "first_row_s": 1.0}
SEED = 2026
FIRST_NORAD = 10001
SMALL_OBJECTS = 10
STORED_POINTS = 200
FILE_POINTS = 300
SURVEY = {"period_min": 10.0, "period_max": 20.0, "verdict": "confident"}


def build(path: Path, n_objects: int, n_passes: int, processes: int) -> float:
    """Build an archive unless an identical one is there; returns the build time (0 if reused)."""
    spec = {"objects": n_objects, "passes": n_passes, "points": STORED_POINTS, "seed": SEED}
    marker = path / "bench-spec.json"
    if marker.exists() and json.loads(marker.read_text()) == spec:
        return 0.0
    shutil.rmtree(path, ignore_errors=True)
    from rsodb.samples.synthetic import write_synthetic_archive

    started = time.perf_counter()
    write_synthetic_archive(path, n_objects, n_passes, n_points=STORED_POINTS, seed=SEED, processes=processes)
    elapsed = time.perf_counter() - started
    marker.write_text(json.dumps(spec))
    return elapsed


def _night_files(args) -> int:
    from rsodb.samples.synthetic import write_synthetic_corpus

    directory, n_files, seed, indices, night_utc, first_norad = args
    return len(
        write_synthetic_corpus(
            directory,
            n_files,
            FILE_POINTS,
            n_files,
            seed=seed,
            first_norad=first_norad,
            indices=indices,
            first_utc=night_utc,
        )
    )


def write_night(
    directory: Path, n_files: int, seed: int, night_utc: str, processes: int, first_norad: int = FIRST_NORAD
) -> None:
    """One new pass for each of `n_files` objects from `first_norad` on, on the night of `night_utc`
    (after every stored pass)."""
    from concurrent.futures import ProcessPoolExecutor

    step = -(-n_files // (4 * processes))
    pieces = [
        (directory, n_files, seed, range(i, min(i + step, n_files)), night_utc, first_norad)
        for i in range(0, n_files, step)
    ]
    with ProcessPoolExecutor(processes) as pool:
        assert sum(pool.map(_night_files, pieces)) == n_files


IMPORT_FLOOR = [sys.executable, "-c", "import rsodb.cli, rsodb.archive"]


def rsodb(*args: str) -> list[str]:
    return [sys.executable, "-m", "rsodb", *args]


def wall_s(argv: list[str]) -> float:
    """Seconds from start to exit of a command (its output thrown away); it must succeed."""
    started = time.perf_counter()
    done = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    elapsed = time.perf_counter() - started
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed ({done.returncode}): {done.stderr[-500:]}")
    return elapsed


def first_row_s(archive: Path) -> tuple[float, float]:
    """Seconds until ``rsodb ls`` prints its first pass, and until it has printed all."""
    started = time.perf_counter()
    process = subprocess.Popen(rsodb("ls", "--archive", str(archive)), stdout=subprocess.PIPE, cwd=ROOT)
    process.stdout.readline()  # the header
    process.stdout.readline()  # the first pass
    first = time.perf_counter() - started
    for _ in process.stdout:
        pass
    process.wait()
    return first, time.perf_counter() - started


def _in_process(mode: str, archive: str, corpus: str) -> dict:
    """Runs in a child process: the survey query after opening, the archive's share of the
    one-object commands (`corpus` is then the NORAD number), or an ingest."""
    from rsodb.archive import Archive
    from rsodb.samples.synthetic import SyntheticPeriod

    opened = time.perf_counter()
    target = Archive(archive)
    if mode == "object":
        norad = int(corpus)
        timed = {"open_s": time.perf_counter() - opened}
        started = time.perf_counter()
        rows = target.summaries(norad=norad)
        timed["summaries(norad)"] = time.perf_counter() - started
        started = time.perf_counter()
        stored = target.get(rows[0].pass_id)
        names = target.result_names(stored.pass_id, "periods")
        values = [target.result_values(stored.pass_id, "periods", name) for name in names]
        timed["get + results (show)"] = time.perf_counter() - started
        started = time.perf_counter()
        passes = [target.get(row.pass_id) for row in rows]
        target.store_results(
            (p.pass_id, "periods", "bench", SyntheticPeriod(float(len(p)), 0.01, "confident")) for p in passes
        )
        timed["get all + store results (periods)"] = time.perf_counter() - started
        assert values and len(passes) == len(rows)
        return timed
    if mode == "survey":
        target.catalog()  # pandas and the index warm, as in a notebook
        started = time.perf_counter()
        frame = target.catalog(**SURVEY)
        return {"rows": len(frame), "query_s": time.perf_counter() - started, "open_s": started - opened}
    started = time.perf_counter()
    report = target.ingest([corpus], progress=False)
    elapsed = time.perf_counter() - started
    assert report.ok and len(report.ingested) == report.n_files, report.summary()[:2000]
    return {"files": report.n_files, "elapsed_s": elapsed}


def in_process(mode: str, archive: Path, corpus: Path | str = "") -> dict:
    argv = [sys.executable, __file__, "_in_process", mode, str(archive), str(corpus)]
    output = subprocess.run(argv, check=True, capture_output=True, text=True, cwd=ROOT).stdout
    return json.loads(output.splitlines()[-1])


def passes_per_object(path: Path, first_norad: int, count: int) -> float:
    """Mean number of passes stored for objects `first_norad` .. `first_norad + count - 1`."""
    from rsodb.archive import Archive

    frame = Archive(path).catalog(all_versions=True)
    counts = frame["norad"].value_counts()
    return float(np.mean([counts.get(norad, 0) for norad in range(first_norad, first_norad + count)]))


def targets_of(path: Path) -> tuple[str, str]:
    """An object in the middle of the archive and its first pass id."""
    from rsodb.archive import Archive

    archive = Archive(path)
    norads = sorted({row.norad for row in archive.iter_summaries()})
    norad = norads[len(norads) // 2]
    return str(norad), archive.summaries(norad=norad)[0].pass_id


def run(n_objects: int, n_passes: int, ingest_files: int, repeats: int, directory: Path, processes: int) -> dict:
    directory.mkdir(parents=True, exist_ok=True)
    big, small = directory / f"big-{n_objects}-{n_passes}", directory / "small"
    build_s = build(big, n_objects, n_passes, processes)
    build(small, SMALL_OBJECTS, SMALL_OBJECTS * n_passes // n_objects, 1)
    print(f"archives ready (big built in {build_s:.0f} s; 0 = reused)", flush=True)
    times: dict[str, dict[str, list[float]]] = {}

    def add(name: str, which: str, value: float) -> None:
        times.setdefault(name, {"big": [], "small": []})[which].append(value)

    # Query commands, big and small in turn.
    targets = {"big": targets_of(big), "small": targets_of(small)}
    paths = {"big": big, "small": small}
    for which, (norad, _) in targets.items():  # the survey of the object, stored once (not timed)
        wall_s(rsodb("periods", "--archive", str(paths[which]), "--object", norad, "--quiet"))
    for repeat in range(repeats):
        for which in ("big", "small"):
            norad, pass_id = targets[which]
            archive = str(paths[which])
            # The floor of every command: Python's start-up and the imports of the archive commands.
            add("floor: python -c 'import rsodb.cli, rsodb.archive'", which, wall_s(IMPORT_FLOOR))
            add("rsodb ls --norad N", which, wall_s(rsodb("ls", "--archive", archive, "--norad", norad)))
            add("rsodb show PASS", which, wall_s(rsodb("show", pass_id, "--archive", archive)))
            add(
                "rsodb periods --object N",
                which,
                wall_s(rsodb("periods", "--archive", archive, "--object", norad, "--quiet")),
            )
            add(
                "rsodb periods --object N --force",
                which,
                wall_s(rsodb("periods", "--archive", archive, "--object", norad, "--quiet", "--force")),
            )
            survey = ["--period-min", str(SURVEY["period_min"]), "--period-max", str(SURVEY["period_max"])]
            add(
                "rsodb ls (survey filters) --json",
                which,
                wall_s(rsodb("ls", "--archive", archive, *survey, "--verdict", SURVEY["verdict"], "--json")),
            )
            query = in_process("survey", paths[which])
            add("Archive.catalog(survey filters), opened", which, query["query_s"])
            first, whole = first_row_s(paths[which])
            add("rsodb ls: first row", which, first)
            add("rsodb ls: every row", which, whole)
            for name, value in in_process("object", paths[which], norad).items():
                if name != "open_s":
                    add(f"archive side: {name}", which, value)
        print(f"  queries, repeat {repeat + 1}: done", flush=True)
    rows = {which: in_process("survey", paths[which])["rows"] for which in paths}

    # Ingest of a night: one new file per object, into the big archive and into an empty one.
    # Each night goes to the next `ingest_files` objects, so that runs of the bench do not pile
    # nights onto the same objects (a commit's cost grows with its object's file).
    ingest_rates = {"big": [], "empty": []}
    stored_before = []  # passes stored per object of the night, before it
    with tempfile.TemporaryDirectory(prefix="rsodb-night-", dir=directory) as tmp:
        for repeat in range(repeats):
            night = Path(tmp) / f"night-{repeat}"
            nights_before = len(list(directory.glob("nights-*"))) * repeats + repeat
            night_utc = str(np.datetime64("2026-01-01T18:00") + np.timedelta64(nights_before, "D"))
            first = FIRST_NORAD + (nights_before * ingest_files) % max(1, n_objects - ingest_files + 1)
            write_night(night, ingest_files, SEED + nights_before, night_utc, processes, first)
            stored_before.append(passes_per_object(big, first, ingest_files))
            empty = Path(tmp) / f"empty-{repeat}"
            for which, target in (("big", big), ("empty", empty)):
                result = in_process("ingest", target, night)
                ingest_rates[which].append(result["files"] / result["elapsed_s"])
            shutil.rmtree(empty)
            print(f"  ingest, repeat {repeat + 1}: {ingest_rates['big'][-1]:.0f} files/s", flush=True)
        (directory / f"nights-{time.time_ns()}").touch()  # the next run ingests other nights
    return {
        "objects": n_objects,
        "passes": n_passes,
        "stored_points": STORED_POINTS,
        "ingest_files": ingest_files,
        "file_points": FILE_POINTS,
        "repeats": repeats,
        "build_s": build_s,
        "times": times,
        "survey_rows": rows,
        "ingest_files_per_s": ingest_rates,
        "night_objects_passes_before": stored_before,
        "archive_mib": sum(p.stat().st_size for p in (big / "objects").glob("*.h5")) / 2**20,
    }


def medians(result: dict) -> dict:
    return {name: {k: statistics.median(v) for k, v in pair.items()} for name, pair in result["times"].items()}


def report(result: dict) -> str:
    med = medians(result)
    rates = {k: statistics.median(v) for k, v in result["ingest_files_per_s"].items()}
    load = os.getloadavg()
    lines = [
        f"## Archive at survey scale ({today()}, bench/archive_scale.py)",
        "",
        f"A synthetic archive of {result['objects']} objects and {result['passes']} passes "
        f"({result['stored_points']} samples each, {result['archive_mib']:.0f} MiB of HDF5, one stored period "
        f"result per pass) against one of {SMALL_OBJECTS} objects with as many passes per object. Commands are "
        f"timed as whole processes (Python start-up included), big and small in turn; median of "
        f"{result['repeats']} run(s). {os.cpu_count()} CPUs ({platform.processor() or platform.machine()}), "
        f"Python {platform.python_version()}; load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} at the "
        "end: the machine is shared, so times are upper bounds."
        + (f" The big archive was built in {result['build_s']:.0f} s." if result["build_s"] else ""),
        "",
        f"| operation | {result['objects']} objects, s | {SMALL_OBJECTS} objects, s | ratio | target |",
        "|---|---:|---:|---:|---|",
    ]
    target = {
        "rsodb ls --norad N": "<= 0.5 s, <= 1.5x",
        "rsodb show PASS": "<= 0.5 s, <= 1.5x",
        "rsodb periods --object N": "<= 0.5 s, <= 1.5x",
        "rsodb periods --object N --force": "<= 1.5x",
        "Archive.catalog(survey filters), opened": "<= 1 s",
        "rsodb ls (survey filters) --json": "<= 1 s",
        "rsodb ls: first row": "<= 1 s",
        "archive side: summaries(norad)": "<= 1.5x",
        "archive side: get + results (show)": "<= 1.5x",
        "archive side: get all + store results (periods)": "<= 1.5x",
    }
    for name, pair in med.items():
        lines.append(
            f"| {name} | {pair['big']:.3f} | {pair['small']:.3f} | {pair['big'] / pair['small']:.2f} | "
            f"{target.get(name, '')} |"
        )
    lines += [
        "",
        "`rsodb periods --object N` reports the object's stored results, found from the same inputs "
        "(the survey is run once, untimed, before the repeats); with `--force` it searches every pass "
        "of the object again (the search's imports and work, the same on both archives).",
        "",
        "The 'archive side' rows time, in a process that has opened the archive, what the archive does "
        "for `ls --norad`, `show` and `periods --object` (reading the object's passes and storing a result "
        "for each), without Python's start-up and imports or the period search itself.",
        "",
        f"The survey query (period {SURVEY['period_min']:g}-{SURVEY['period_max']:g} s, verdict "
        f"{SURVEY['verdict']}) selects {result['survey_rows']['big']} of {result['passes']} passes. Ingest of a "
        f"night ({result['ingest_files']} new {result['file_points']}-row ccd_phot files, one per object, "
        f"each night the next {result['ingest_files']} objects; they held "
        f"{', '.join(f'{n:.1f}' for n in result['night_objects_passes_before'])} passes each before it): "
        f"{rates['big']:.0f} files/s into the big archive, {rates['empty']:.0f} files/s into an empty one "
        f"(ratio {rates['big'] / rates['empty']:.2f}); target >= {TARGETS['ingest_files_per_s']:.0f} files/s.",
        "",
    ]
    return "\n".join(lines)


def headline_figures(result: dict) -> list[dict]:
    med = medians(result)
    rates = {k: statistics.median(v) for k, v in result["ingest_files_per_s"].items()}
    figures = [
        figure(
            f"ingest of a night into {result['passes']} passes",
            f"{rates['big']:.0f} files/s",
            f">= {TARGETS['ingest_files_per_s']:.0f} files/s",
        )
    ]
    for name in (
        "rsodb ls --norad N",
        "rsodb show PASS",
        "rsodb periods --object N",
        "rsodb periods --object N --force",
    ):
        pair = med[name]
        target = "<= 1.5x" if name.endswith("--force") else "<= 0.5 s, <= 1.5x"
        figures.append(figure(name, f"{pair['big']:.2f} s ({pair['big'] / pair['small']:.2f}x 10 objects)", target))
    figures.append(
        figure(
            "survey query over all passes", f"{med['Archive.catalog(survey filters), opened']['big']:.3f} s", "<= 1 s"
        )
    )
    figures.append(figure("rsodb ls: first row", f"{med['rsodb ls: first row']['big']:.2f} s", "<= 1 s"))
    return figures


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "_in_process":
        print(json.dumps(_in_process(*argv[1:4])))
        return 0
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--objects", type=int, default=20_000)
    parser.add_argument("--passes", type=int, default=100_000)
    parser.add_argument("--ingest-files", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--processes", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()) / "rsodb-archive-scale")
    parser.add_argument("--no-record", action="store_true", help="print only; record nothing")
    args = parser.parse_args(argv)
    result = run(args.objects, args.passes, args.ingest_files, args.repeats, args.dir, args.processes)
    text = report(result)
    print(text)
    if not args.no_record:
        record("archive_scale", command("archive_scale.py", argv), headline_figures(result), text, data=result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
