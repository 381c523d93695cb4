"""The results of bench/side_by_side.sh's rounds, for compare_builds.sh and compare_counter.sh."""
import json


def side_by_side_results(work, rounds, threads):
    """Yields (side, name, benchmark) for every entry of every round's JSON: side is "base"
    or "new", name the case without its /threads:N and /manual_time suffixes."""
    for side in ("base", "new"):
        for r in range(rounds):
            for b in json.load(open(f"{work}/{side}.{r}.json"))["benchmarks"]:
                name = b["run_name"].replace(f"/threads:{threads}", "").replace("/manual_time", "")
                yield side, name, b
