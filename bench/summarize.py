#!/usr/bin/env python3
"""Turns the JSON of motionlod_bench_bake into the markdown tables of docs/PERFORMANCE.md.

Usage:
  summarize.py RESULTS.json [--command "..."] [--doc docs/PERFORMANCE.md] [--target 3]

Without --doc the markdown goes to stdout. With --doc the text between the lines
"<!-- BEGIN RESULTS -->" and "<!-- END RESULTS -->" of that file is replaced (the rest of
the file, the analysis written by hand, is kept).

Every figure is a median over the repetitions of one benchmark (per-repetition entries of
the JSON; aggregates are ignored). A ratio is the ratio of two medians measured in the
same run: bake / skinning pass of the same case and thread count, naive / fast of the same
case. Standard library only.
"""

import argparse
import datetime
import json
import os
import re
import statistics
import subprocess
import sys

BEGIN, END = "<!-- BEGIN RESULTS -->", "<!-- END RESULTS -->"
VARIANTS = ["vp", "vpno", "vp+pd", "vpno+pd"]
SUFFIXES = re.compile(r"(/iterations:\d+|/repeats:\d+|/manual_time|/real_time)+$")


def seconds(entry):
    scale = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}[entry.get("time_unit", "ns")]
    return entry["real_time"] * scale


def load(path):
    with open(path) as f:
        data = json.load(f)
    runs = {}  # name -> {"times": [...], "counters": {name: [...]}, "error": str}
    for entry in data.get("benchmarks", []):
        if entry.get("run_type", "iteration") != "iteration":
            continue
        name = SUFFIXES.sub("", entry.get("run_name", entry["name"]))
        run = runs.setdefault(name, {"times": [], "counters": {}, "error": None})
        if entry.get("error_occurred"):
            run["error"] = entry.get("error_message", "error")
            continue
        run["times"].append(seconds(entry))
        for key, value in entry.items():
            if isinstance(value, (int, float)) and key not in (
                    "real_time", "cpu_time", "iterations", "repetitions", "repetition_index",
                    "threads", "family_index", "per_family_instance_index"):
                run["counters"].setdefault(key, []).append(value)
    return data.get("context", {}), runs


def median(values):
    return statistics.median(values) if values else None


def cv(runs, name):
    """Coefficient of variation of a benchmark's repetitions (noise), or None."""
    run = runs.get(name)
    if not run or len(run["times"]) < 2:
        return None
    return statistics.stdev(run["times"]) / statistics.mean(run["times"])


def med_time(runs, name):
    run = runs.get(name)
    return median(run["times"]) if run else None


def counter(runs, name, key):
    run = runs.get(name)
    if not run or key not in run["counters"]:
        return None
    return median(run["counters"][key])


def ms(value):
    if value is None:
        return "–"
    return f"{value * 1e3:.1f}" if value >= 0.01 else f"{value * 1e3:.2f}"


def fmt_ratio(value):
    return "–" if value is None else (f"{value:.1f}x" if value < 100 else f"{value:.0f}x")


def split_cases(runs):
    """{threads: {ladder: {case: {variant: name}}}} and the skin names."""
    bakes, skins = {}, {}
    for name in runs:
        m = re.match(r"^bake/(.+)/([^/]+)/(default|all)/threads:(\d+)$", name)
        if m:
            case, variant, ladder, threads = m.group(1), m.group(2), m.group(3), int(m.group(4))
            bakes.setdefault(threads, {}).setdefault(ladder, {}).setdefault(case, {})[variant] = name
            continue
        m = re.match(r"^skin/(.+)/threads:(\d+)$", name)
        if m:
            skins[(m.group(1), int(m.group(2)))] = name
    return bakes, skins


def shape(runs, name):
    return tuple(counter(runs, name, k) for k in ("vertices", "joints", "frames"))


def bake_table(runs, bakes, skins, threads, ladder, target, lines, tally, noise):
    cases = bakes.get(threads, {}).get(ladder, {})
    if not cases:
        return
    present = [v for v in VARIANTS if any(v in c for c in cases.values())]
    head = ["case", "p", "n", "T"]
    if ladder == "default":
        head.append("levels")
    head += ["skin ms"] + [f"{v} ms (ratio)" for v in present] + ["worst", f"<= {target:g}x"]
    paired = "vpno+pd" in present
    if paired:
        head.append("paired ratio vpno+pd")
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---|" * len(head))
    for case in sorted(cases, key=str.lower):
        variants = cases[case]
        skin = med_time(runs, skins.get((case, threads), ""))
        any_name = next(iter(variants.values()))
        p, n, t = shape(runs, any_name)
        row = [f"`{case}`", f"{p:.0f}" if p else "–", f"{n:.0f}" if n else "–", f"{t:.0f}" if t else "–"]
        if ladder == "default":
            levels = counter(runs, any_name, "levels")
            row.append(f"{levels:.0f}" if levels else "–")
        row.append(ms(skin))
        worst = None
        for v in present:
            name = variants.get(v)
            if not name or runs[name]["error"] or not runs[name]["times"]:
                row.append("error: " + (runs[name]["error"] if name else "missing"))
                worst = float("inf")
                continue
            bake = med_time(runs, name)
            ratio = bake / skin if skin else None
            if ratio is not None:
                worst = ratio if worst is None else max(worst, ratio)
            row.append(f"{ms(bake)} ({fmt_ratio(ratio)})")
        ok = worst is not None and worst <= target
        tally.append(ok)
        row += [fmt_ratio(worst), "pass" if ok else "**fail**"]
        if paired:
            row.append(fmt_ratio(counter(runs, variants.get("vpno+pd", ""), "insitu_ratio")))
        for name in [skins.get((case, threads), "")] + list(variants.values()):
            c = cv(runs, name)
            if c is not None:
                noise.append(c)
        lines.append("| " + " | ".join(row) + " |")


def ladder_stages_table(runs, bakes, threads, lines):
    """The default-ladder bake split by the times of Bake's progress reports."""
    cases = bakes.get(threads, {}).get("default", {})
    rows = []
    for case in sorted(cases, key=str.lower):
        for v in ("vp", "vpno+pd"):  # the cheapest and the default variant
            name = cases[case].get(v)
            if not name or counter(runs, name, "to_first_level_s") is None:
                continue
            total = med_time(runs, name)
            inputs, rank, first, later, count, encode = (
                counter(runs, name, k) for k in ("inputs_s", "rank_s", "to_first_level_s",
                                                 "later_levels_s", "later_level_count", "encode_s"))

            def pct(x):
                return f"{ms(x)} ({100 * x / total:.0f}%)" if total else ms(x)

            rows.append(f"| `{case}` | {v} | {ms(total)} | {pct(inputs)} | {pct(rank)} | {pct(first)} "
                        f"| {pct(later)} ({count:.0f}) | {pct(encode)} |")
    if rows:
        lines.append("| case | variant | bake ms | inputs | rank | Create and the first level "
                     "| later levels and the search (levels) | encode |")
        lines.append("|---|---|---|---|---|---|---|---|")
        lines.extend(rows)


def stages_table(runs, bakes, threads, lines):
    cases = bakes.get(threads, {}).get("all", {})
    rows = []
    for case in sorted(cases, key=str.lower):
        for v in VARIANTS:
            name = cases[case].get(v)
            if not name or counter(runs, name, "solve_s") is None:
                continue
            parts = [counter(runs, name, k) for k in ("inputs_s", "rank_s", "prepare_s", "solve_s", "encode_s")]
            total = sum(x for x in parts if x is not None)
            rows.append(f"| `{case}` | {v} | " + " | ".join(
                f"{ms(x)} ({100 * x / total:.0f}%)" for x in parts) + f" | {ms(total)} |")
    if rows:
        lines.append("| case | variant | inputs ms | rank ms | prepare ms | solve all levels ms | encode ms | sum ms |")
        lines.append("|---|---|---|---|---|---|---|---|")
        lines.extend(rows)


def replica_table(runs, lines):
    rows = []
    for name in sorted(runs, key=str.lower):
        m = re.match(r"^replica/(.+)/([^/]+)/all/threads:(\d+)$", name)
        if not m:
            continue
        case, variant, threads = m.groups()
        bake = med_time(runs, f"bake/{case}/{variant}/all/threads:{threads}")
        replica = med_time(runs, name)
        if bake and replica:
            rows.append(f"| `{case}` | {variant} | {threads} | {ms(bake)} | {ms(replica)} | {replica / bake:.2f} |")
    if rows:
        lines.append("| case | variant | threads | pipeline::Bake all levels ms | bench replica ms | replica / Bake |")
        lines.append("|---|---|---|---|---|---|")
        lines.extend(rows)


def naive_table(runs, skins, lines):
    """The naive solve against the factored one: the range over the cases of each ratio."""
    cases = sorted({n[len("naive/"):] for n in runs if n.startswith("naive/")}, key=str.lower)
    if not cases:
        return
    ratios = {"SolveLevel": [], "SolveLeastSquares": [], "one skinning pass (1 thread)": []}
    for case in cases:
        naive = med_time(runs, "naive/" + case)
        for key, other in (("SolveLevel", med_time(runs, "level/" + case)),
                           ("SolveLeastSquares", med_time(runs, "ls/" + case)),
                           ("one skinning pass (1 thread)", med_time(runs, skins.get((case, 1), "")))):
            if naive and other:
                ratios[key].append((naive / other, case))
    for key, values in ratios.items():
        if values:
            low, high = min(values), max(values)
            lines.append(f"- naive / {key}: {fmt_ratio(low[0])} (`{low[1]}`) to "
                         f"{fmt_ratio(high[0])} (`{high[1]}`), {len(values)} cases")


def machine(context, command):
    def run(args):
        try:
            return subprocess.run(args, capture_output=True, text=True, check=False).stdout.strip()
        except OSError:
            return ""

    model = "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    if context.get("git"):  # recorded by scripts/bench.sh when the run started
        commit, dirty = context["git"], ""
    else:
        commit = run(["git", "-C", root, "rev-parse", "--short", "HEAD"]) or "unknown"
        dirty = run(["git", "-C", root, "status", "--porcelain", "--untracked-files=no"])
    version = context.get("library_version") or run(
        ["dpkg-query", "-W", "-f=${Version}", "libbenchmark-dev"]) or "?"
    facts = [
        f"- date of the run: {context.get('date', datetime.datetime.now().isoformat())}",
        f"- git commit: `{commit}`" + (" (with uncommitted changes)" if dirty else ""),
        f"- CPU: {model}, nproc = {run(['nproc']) or os.cpu_count()}, "
        f"{context.get('mhz_per_cpu', '?')} MHz; load average at the start "
        f"{', '.join(f'{x:.2f}' for x in context.get('load_avg', [])) or '?'}",
        f"- Google Benchmark {version} "
        f"(Debian's libbenchmark, which reports itself as a debug build: that concerns "
        f"the harness, not the code measured, which is Release `-O3`)",
    ]
    if context.get("simd"):
        facts.append(f"- hot loops: the `{context['simd']}` version (core/simd.h)")
    if command:
        facts.append(f"- command: `{command}`")
    return facts


def render(context, runs, command, target):
    bakes, skins = split_cases(runs)
    lines = ["## Machine and command", ""] + machine(context, command) + [""]
    errors = [f"- `{n}`: {r['error']}" for n, r in sorted(runs.items()) if r["error"]]
    summary = []
    body = []
    for threads in sorted(bakes):
        for ladder, title in (("default", "Default ladder of every file"),
                              ("all", "Every level (`@Nv`: subdivided to 10k+ vertices, the target; others: the original mesh)")):
            if ladder not in bakes[threads]:
                continue
            tally, noise = [], []
            body += [f"## {title}, {threads} thread{'s' if threads > 1 else ''}", ""]
            bake_table(runs, bakes, skins, threads, ladder, target, body, tally, noise)
            body.append("")
            noise_text = (f"; repetitions vary by {100 * median(noise):.0f}% (median coefficient of "
                          f"variation), {100 * max(noise):.0f}% at worst") if noise else ""
            summary.append(f"- {title.split(',')[0].split(' (')[0]}, {threads} thread"
                           f"{'s' if threads > 1 else ''}: {sum(tally)} of {len(tally)} cases within "
                           f"{target:g}x in every variant{noise_text}")
        if threads == 1 and "default" in bakes[threads]:
            body += ["### Where the default-ladder bake goes, 1 thread (times of Bake's progress reports; "
                     "medians of per-iteration means)", "",
                     "`Create and the first level` is the time from the \"prepare\" report to the first "
                     "finished level (PreparedMotion::Create and the full level, whose solve is the original "
                     "matrices); `later levels and the search` runs from there to the last finished level: the "
                     "ladder's other levels, the bisection probes of the smallest useful level (on at most 64 "
                     "strided frames) and that level.", ""]
            ladder_stages_table(runs, bakes, threads, body)
            body.append("")
        if "all" in bakes[threads]:
            body += [f"### Where the every-level bake goes, {threads} thread{'s' if threads > 1 else ''}"
                     " (median of per-iteration stage means)", ""]
            stages_table(runs, bakes, threads, body)
            body.append("")
    replica = []
    replica_table(runs, replica)
    if replica:
        body += ["## Check: the bench's every-level replica against pipeline::Bake (original meshes)", ""] + replica + [""]
    body += ["## Naive per-frame dense solve against the factored solve (1 thread, level round(n/2))", ""]
    naive_table(runs, skins, body)
    body.append("")
    lines += ["## Summary against the target", ""] + summary + [""] + body
    if errors:
        lines += ["## Errors", ""] + errors + [""]
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("json")
    parser.add_argument("--command", default="")
    parser.add_argument("--doc")
    parser.add_argument("--target", type=float, default=3.0)
    args = parser.parse_args()
    context, runs = load(args.json)
    text = render(context, runs, args.command, args.target)
    if not args.doc:
        sys.stdout.write(text + "\n")
        return 0
    with open(args.doc) as f:
        doc = f.read()
    if BEGIN not in doc or END not in doc:
        sys.stderr.write(f"{args.doc} has no {BEGIN} ... {END} section\n")
        return 1
    head, rest = doc.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    with open(args.doc, "w") as f:
        f.write(head + BEGIN + "\n" + text + "\n" + END + tail)
    return 0


if __name__ == "__main__":
    sys.exit(main())
