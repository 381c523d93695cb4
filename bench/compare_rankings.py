#!/usr/bin/env python3
"""Joint rankings of two builds side by side, to check that a change to the ranking moves
only the order of joints that barely move: for every character and motion of
../shared/data that has a clip of its own, `motionlod rank FILE --json --threads 1` of each
build, then the largest difference of the rotational factor (radians) and the ranks where
the removal orders differ.

  python3 bench/compare_rankings.py BASE_BUILD NEW_BUILD

BASE_BUILD and NEW_BUILD hold tools/motionlod (any build of the project)."""
import json
import pathlib
import subprocess
import sys

FORMATS = {".glb", ".gltf", ".fbx", ".dae", ".bvh", ".x", ".smd"}


def ranking(build, path):
    run = subprocess.run([f"{build}/tools/motionlod", "rank", str(path), "--json", "--threads", "1"],
                         capture_output=True, text=True)
    return json.loads(run.stdout) if run.returncode == 0 else None


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: compare_rankings.py BASE_BUILD NEW_BUILD")
    base, new = sys.argv[1], sys.argv[2]
    data = pathlib.Path(__file__).resolve().parent.parent.parent / "shared" / "data"
    files = sorted(p for folder in ("characters", "motions") for p in (data / folder).iterdir()
                   if p.suffix.lower() in FORMATS)
    if not files:
        sys.exit(f"compare_rankings: no character or motion under {data}")
    compared = reordered = 0
    largest = 0.0
    print("| file | largest difference of rotational (rad) | removal order |")
    print("|---|---|---|")
    for path in files:
        a, b = ranking(base, path), ranking(new, path)
        if a is None or b is None:
            print(f"| `{path.name}` | no clip of its own | |")
            continue
        compared += 1
        rotational = {row["index"]: row["rotational"] for row in b}
        difference = max(abs(row["rotational"] - rotational[row["index"]]) for row in a)
        largest = max(largest, difference)
        changed = [rank + 1 for rank, (x, y) in enumerate(zip(a, b)) if x["index"] != y["index"]]
        reordered += bool(changed)
        order = "same" if not changed else "differs at ranks " + ", ".join(map(str, changed))
        print(f"| `{path.name}` | {difference:.2g} | {order} |")
    print(f"\n{compared} files compared: the largest difference {largest:.2g} rad, "
          f"the removal order differs in {reordered}")


if __name__ == "__main__":
    main()
