#!/usr/bin/env python3
"""Round 27: how long each thread is busy in each stage of one traced bake.

Reads what `TRACE_RAW=1 motionlod_trace_bake FILE VARIANT 2` prints after its medians
(round26-pool-trace.patch): one line per event, "begin end duration Tn label [i/n]". A
thread's busy time in a stage is the union of the pieces it ran between two of the marks
(nested pieces counted once); the rest of the stage it waited.
  TRACE_RAW=1 build-bench/bench/motionlod_trace_bake ../shared/data/characters/Fox.glb vp+pd 2 \\
    | python3 bench/experiments/round27-thread-waits.py
"""
import re
import sys

events, marks = [], []
for line in sys.stdin:
    m = re.match(r'\s*([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+T(\d+)\s+(.*) \[(\d+)/(\d+)\]', line)
    if not m:
        continue
    begin, end, thread, label = float(m[1]), float(m[2]), m[4], m[5]
    if label.startswith('MARK'):
        if not label[5:].startswith('C'):  # Create's own marks are inside a stage
            marks.append((begin, label[5:]))
    else:
        events.append((begin, end, thread))
marks.sort()


def busy(thread, lo, hi):
    spans = sorted((max(b, lo), min(e, hi)) for b, e, t in events if t == thread and e > lo and b < hi)
    total, current = 0.0, None
    for b, e in spans:
        if current and b <= current[1]:
            current[1] = max(current[1], e)
        else:
            if current:
                total += current[1] - current[0]
            current = [b, e]
    return total + (current[1] - current[0] if current else 0.0)


threads = sorted({t for _, _, t in events})
for (lo, name), (hi, _) in zip(marks, marks[1:]):
    print(f'{name:12s} {hi - lo:7.1f} us  busy: ' + '  '.join(f'T{t} {busy(t, lo, hi):6.1f}' for t in threads))
