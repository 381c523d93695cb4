# Round 34 (docs/PERFORMANCE.md): two or more commands that print the line of
# round33-every-level-trace.cc with round34-every-level-medians.patch, run alternately
# ROUNDS times; per stage, the median of their medians
# and the fastest. Each command is LABEL::COMMAND LINE, e.g.
#   python3 bench/experiments/round34-every-level-ab.py 8 \
#     "old::/tmp/medians_old ../shared/data/characters/Orc.gltf vpno+pd 2 16089 60" \
#     "new::/tmp/medians_new ../shared/data/characters/Orc.gltf vpno+pd 2 16089 60"
import subprocess, sys, statistics
rounds = int(sys.argv[1]); cmds = sys.argv[2:]
res = {c: [] for c in cmds}
for r in range(rounds):
    for c in cmds:
        label, cmd = c.split('::', 1)
        out = subprocess.run(cmd, shell=True, capture_output=True, text=True).stdout.split()
        res[c].append({k: float(v) for k, v in (x.split('=') for x in out)})
keys = ['inputs', 'rank+create', 'solve', 'encode', 'total']
print('| run | ' + ' | '.join(keys) + ' |')
for c in cmds:
    label = c.split('::', 1)[0]
    print(f'| {label} median | ' + ' | '.join(f"{statistics.median(x[k] for x in res[c]):.1f}" for k in keys) + ' |')
    print(f'| {label} fastest | ' + ' | '.join(f"{min(x[k] for x in res[c]):.1f}" for k in keys) + ' |')
