"""A separate process for the archive's crash and concurrency tests.

    python tests/archive_worker.py ingest ARCHIVE PATH... [--workers N] [--interval S]
                                          [--start-after FILE] [--commit-pause S]
        Ingest PATHs (once FILE exists, if given; each object commit followed by a pause of S
        seconds, if given, so that two ingests surely overlap). Prints ``START`` once ready,
        ``BEGIN <norad> ...`` before each round of object commits and one JSON line per object
        committed after its rename (``{"commit": norad, "files": [[path, [pass_id, ...]], ...], "present": [...]}``),
        then ``DONE <json report>``.
    python tests/archive_worker.py read ARCHIVE MANIFEST STOPFILE
        Until STOPFILE exists (and once more after), repeatedly open the archive, read every pass and compare it with
        a fresh read of its source file (MANIFEST: JSON list of the corpus paths). Prints
        ``READ <passes checked>`` per round, ``ERROR <message>`` for any mismatch, then
        ``DONE <rounds> <passes checked>``.

Every line is flushed at once, so a test that SIGKILLs this process knows exactly which
commits had completed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path
import sys
import time

PROJECT_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(PROJECT_ROOT))

import numpy as np  # noqa: E402

import ingest  # noqa: E402
from ingest.observation import ARRAY_FIELDS  # noqa: E402
from rsodb.archive import Archive, CommitEvent  # noqa: E402


def say(line: str) -> None:
    sys.stdout.write(line + "\n")
    sys.stdout.flush()


def run_ingest(args) -> int:
    archive = Archive(args.archive)
    commit_many = archive.commit_many

    def announced_commit_many(batches, *rest, **options):
        say("BEGIN " + " ".join(str(norad) for norad in sorted(batches)))
        result = commit_many(batches, *rest, **options)
        time.sleep(args.commit_pause)
        return result

    archive.commit_many = announced_commit_many  # only this process's instance; the library is unchanged

    def on_commit(event: CommitEvent) -> None:
        say(
            json.dumps(
                {
                    "commit": event.norad,
                    "files": [[item.path, list(item.pass_ids)] for item in event.ingested],
                    "present": list(event.already_present),
                }
            )
        )

    say("START")
    while args.start_after and not Path(args.start_after).exists():
        time.sleep(0.005)
    report = archive.ingest(
        args.paths, progress=False, workers=args.workers, on_commit=on_commit, commit_interval_s=args.interval
    )
    say("DONE " + json.dumps(report.to_dict()))
    return 0


def same_arrays(stored, original) -> str | None:
    """None when every per-sample array matches exactly, else the first differing name."""
    for name in ARRAY_FIELDS:
        if not np.array_equal(getattr(stored, name), getattr(original, name)):
            return name
    return None


def run_reader(args) -> int:
    sources = {}
    for path in json.loads(Path(args.manifest).read_text()):
        sources[hashlib.sha256(Path(path).read_bytes()).hexdigest()] = path
    cache = {}
    stop = Path(args.stopfile)
    rounds = checked = errors = 0
    while True:
        last_round = stop.exists()  # a round begun after the stop file appeared sees the final state
        try:
            archive = Archive(args.archive, create=False)
        except ValueError:
            if last_round:
                break
            continue  # the ingests have not created it yet
        stored = archive.passes(all_versions=True)
        for item in stored:
            path = sources.get(item.source_sha256)
            if path is None:
                say(f"ERROR {item.pass_id}: sha256 {item.source_sha256} is not a corpus file")
                errors += 1
                continue
            if path not in cache:
                (cache[path],) = ingest.read_file(path)
            differing = same_arrays(item, cache[path])
            if differing is not None:
                say(f"ERROR {item.pass_id}: {differing} differs from {path}")
                errors += 1
            checked += 1
        rows = archive.summaries(all_versions=True)
        shas = [row.source_sha256 for row in rows]
        if len(shas) != len(set(shas)):
            say(f"ERROR a file is stored twice: {len(shas)} rows, {len(set(shas))} distinct")
            errors += 1
        rounds += 1
        say(f"READ {len(stored)}")
        if last_round:
            break
    say(f"DONE {rounds} {checked}")
    return 1 if errors else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="mode", required=True)
    p_ingest = sub.add_parser("ingest")
    p_ingest.add_argument("archive")
    p_ingest.add_argument("paths", nargs="+")
    p_ingest.add_argument("--workers", type=int, default=1)
    p_ingest.add_argument("--interval", type=float, default=0.02)
    p_ingest.add_argument("--start-after", default=None)
    p_ingest.add_argument("--commit-pause", type=float, default=0.0)
    p_ingest.set_defaults(func=run_ingest)
    p_read = sub.add_parser("read")
    p_read.add_argument("archive")
    p_read.add_argument("manifest")
    p_read.add_argument("stopfile")
    p_read.set_defaults(func=run_reader)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
