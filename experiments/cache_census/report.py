"""Sum the per-process totals that ``sitecustomize.py`` (this folder) wrote: the test run's
compilations and its compilation cache's keys, lookups, writes and hits.

Usage: ``python experiments/cache_census/report.py FOLDER``.
"""

import argparse
import collections
import json
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    args = parser.parse_args()
    seconds, calls = collections.Counter(), collections.Counter()
    files = sorted(args.folder.glob("*.json"))
    for path in files:
        totals = json.loads(path.read_text())
        seconds.update(totals["seconds"])
        calls.update(totals["calls"])
    print(f"{len(files)} processes")
    print("| what | calls | seconds |\n|---|---|---|")
    for tag in ("compile", "key", "lookup", "reading hits", "write", "saved by hits"):
        print(f"| {tag} | {calls[tag]:,} | {seconds[tag]:.1f} |")
    cost = seconds["key"] + seconds["lookup"] + seconds["write"] - seconds["reading hits"]
    print(
        f"\nthe cache's cost besides reading its hits: {cost:.1f} s; "
        f"saved by its hits, net of reading them: {seconds['saved by hits']:.1f} s"
    )


if __name__ == "__main__":
    main()
