"""Random probe of the whole path on realistic twins (issue 24): simulate-tracker → import
three-reflector (no guesses, payload unknown) → identify (all reflectors, and reflector 1 alone) →
diagnose, and with CV=1 crossval over the three reflectors; each seed draws its own twin.

Each seed draws 300–982 stops, 0–150 removed rows, a 0.3–3 kg plate, 0.004–0.03° of pose-to-pose
turn, up to three hysteresis terms, and (at random) a cyclic error, a coupling 2→3 and link
bending; with MIX2=1 also a cubic compliance and cyclic errors of harmonics up to 40; with BIG=1
hysteresis on up to six joints, up to 0.035°. It checks
what a verdict promises: a named verdict's shrink table ends lower, every named term's gain is
positive, a named backlash lies within 4 σ of its truth, each reflector's held-out mean within
10 % of the pooled one; and prints the verdict, the named or suspected terms and the payload's
z-score beside the truth, for a reader to compare with the drawn effects.

    cargo build --release
    CV=1 MIX2=1 python3 scripts/probe_twins.py 200 20 /tmp/probe

(first seed, seeds, a scratch folder; ROBOCAL=path/to/robocal to use another binary). A line
ending in PROBLEMS is a promise broken. BENCHMARKS.md has the figures.
"""
import json, random, subprocess, sys, os, re
B = os.path.abspath(os.environ.get('ROBOCAL', 'target/release/robocal'))
start, n, scratch = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
def run(args, cwd):
    p = subprocess.run([B] + args, cwd=cwd, capture_output=True, text=True)
    return p.returncode, p.stdout + p.stderr
def true_effect(e, spec):
    """Whether named effect `e` (the verdict's JSON) is the drawn effect `spec`."""
    kind, *kv = spec.split(':')
    kv = dict(x.split('=') for x in kv)
    j = e.get('joint')
    if e['name'] == 'backlash' and kind == 'backlash':
        return j is None or j == int(kv['j'])
    if e['name'] in ('cyclic', 'joint_map') and kind == 'cyclic':
        h = e.get('harmonic')
        return j == int(kv['j']) and (h is None or h == int(kv['h']) or e['name'] == 'joint_map')
    if e['name'] == 'coupling' and kind == 'coupling':
        return e.get('from_joint') == 2 and j == 3
    if e['name'] == 'compliance_cubic' and kind == 'compliance_cubic':
        return j == int(kv['j'])
    return False
for seed in range(start, start + n):
    rng = random.Random(seed)
    eff = []
    big = bool(os.environ.get('BIG'))
    for j in rng.sample(range(1, 7), rng.randint(0, 6 if big else 3)):
        eff.append('backlash:j=%d:deg=%.4f' % (j, rng.uniform(0.003, 0.035 if big else 0.015)))
    if rng.random() < 0.3:
        eff.append('cyclic:j=%d:h=%d:amp_deg=%.4f' % (rng.randint(1, 6), rng.randint(1, 3), rng.uniform(0.005, 0.02)))
    if rng.random() < 0.2:
        eff.append('coupling:from=2:to=3:ratio=%.5f' % rng.uniform(5e-4, 2e-3))
    if rng.random() < 0.15:
        eff.append('link_bending:deg_per_nm=%.5f' % rng.uniform(0.001, 0.004))
    if os.environ.get('MIX2'):
        if rng.random() < 0.3: eff.append('compliance_cubic:j=%d:d=%.2e' % (rng.choice([2, 3]), rng.uniform(1e-7, 4e-7)))
        if rng.random() < 0.3: eff.append('cyclic:j=%d:h=%d:amp_deg=%.4f' % (rng.randint(1, 3), rng.randint(1, 40), rng.uniform(0.005, 0.015)))
    poses = rng.choice([300, 500, 982, 982])
    removed = rng.choice([0, 10, 50, 150]) if poses > 300 else rng.choice([0, 10])
    pay = rng.uniform(0.3, 3.0)
    jit = rng.uniform(0.004, 0.03)
    d = os.path.join(scratch, str(seed))
    os.makedirs(d, exist_ok=True)
    sim = ['simulate-tracker', '--seed', str(seed), '--poses', str(poses), '--removed', str(removed), '--payload-kg', '%.2f' % pay,
           '--jitter-deg', '%.4f' % jit, '--effects=' + ','.join(eff), '--out-dir', 'tw']
    rc, out = run(sim, d)
    desc = 'seed %d poses %d rm %d pay %.2f jit %.4f eff [%s]' % (seed, poses, removed, pay, jit, ','.join(eff))
    if rc: print(desc, 'SIM FAIL', out[-300:]); continue
    imp = ['import', 'three-reflector', '--robot', 'irb120', '--joints', 'tw/run-joints.txt'] + sum([['--positions', 'tw/run-smr%d.txt' % k] for k in (1, 2, 3)], []) + ['--out', 'cell.json']
    rc, out = run(imp, d)
    if rc: print(desc, 'IMPORT FAIL', out[-300:]); continue
    rc, out = run(['identify', 'cell.json', '--out', 'all.json'], d)
    if rc: print(desc, 'IDENTIFY FAIL', out[-400:]); continue
    res = re.search(r'residual RMS ([0-9.]+) mm', out)
    rc1, out1 = run(['identify', 'cell.json', '--sessions', 'reflector-1', '--out', 'r1.json'], d)
    if rc1: print(desc, 'IDENTIFY R1 FAIL', out1[-400:])
    rc, out = run(['diagnose', 'all.json', 'cell.json', '--validation', 'none', '--out', 'dg.json'], d)
    if rc: print(desc, 'DIAGNOSE FAIL', out[-400:]); continue
    g = json.load(open(d + '/dg.json'))
    v = g['verdict']; sh = g['shrink']
    problems = []
    if v['status'] == 'named':
        if not (sh[-1]['mean_mm'] < sh[0]['mean_mm'] and sh[-1]['rms_mm'] <= sh[0]['rms_mm']):
            problems.append('named but shrink %s' % [(round(s['mean_mm'], 4), round(s['rms_mm'], 4)) for s in sh])
        for e in v['effects']:
            if e.get('gain_mean_mm', 0) <= 0 or e.get('gain_rms_mm', 0) <= 0:
                problems.append('named effect %s gains %s %s' % (e['label'], e.get('gain_mean_mm'), e.get('gain_rms_mm')))
    arrows = re.findall(r'held-out mean ([0-9.]+) mm → ([0-9.]+) mm', v['summary'])
    if arrows and v['status'] == 'named':
        a, b = float(arrows[0][0]), float(arrows[-1][1])
        if abs(a - sh[0]['mean_mm']) > 6e-5 or abs(b - sh[-1]['mean_mm']) > 6e-5:
            problems.append('summary %s→%s vs shrink %.4f→%.4f' % (a, b, sh[0]['mean_mm'], sh[-1]['mean_mm']))
    truth_b = {int(x.split(':')[1][2:]): float(x.split('=')[-1]) for x in eff if x.startswith('backlash')}
    for e in v['effects']:
        if e['label'] == 'backlash' and v['status'] == 'named':
            for k, p in enumerate(e['parameters']):
                if p.get('std'):
                    z = (p['estimate'] - truth_b.get(k + 1, 0.0)) / p['std']
                    if abs(z) > 4: problems.append('backlash%d z %.1f (%.5f ± %.5f, truth %.4f)' % (k + 1, z, p['estimate'], p['std'], truth_b.get(k + 1, 0)))
    a = json.load(open(d + '/all.json'))
    pm = [p for p in a['parameters'] if p['name'] == 'tool_mass']
    pay_s = '?'
    if pm:
        p = pm[0]
        mm_ = re.search(r'\(([-0-9.]+) ± ([0-9.]+) kg', p.get('status') or '')
        if mm_: est, sd = float(mm_.group(1)), float(mm_.group(2)); pay_s = 'held %.2f±%.2f z%+.1f' % (est, sd, (est - pay) / sd)
        elif p.get('std'): pay_s = '%.2f±%.2f z%+.1f' % (p['value'], p['std'], (p['value'] - pay) / p['std'])
    if os.environ.get('CV'):
        rc, out = run(['crossval', 'cell.json', '--session', 'reflector-1,reflector-2,reflector-3', '--folds', '5', '--out', 'cv.json'], d)
        if rc: problems.append('CROSSVAL FAIL ' + out[-300:])
        else:
            c = json.load(open(d + '/cv.json'))
            for f in c.get('kfold', []):
                pp = f.get('pooled') or {}
                per = [s.get('mean_mm', -1) for s in pp.get('per_session', [])]
                if f.get('model') == 'default':
                    pay_s += ' | cv %.4f %s' % (pp.get('mean_mm', -1), [round(x, 4) for x in per])
                if per and max(abs(x - pp.get('mean_mm', 0)) for x in per) > 0.1 * pp.get('mean_mm', 1):
                    problems.append('cv %s per-reflector %s vs pooled %.4f' % (f.get('model'), per, pp.get('mean_mm', -1)))
    labels = [e['label'] for e in v['effects']]
    if v['status'] == 'named':
        for e in v['effects']:
            if not any(true_effect(e, x) for x in eff):
                problems.append('WRONG NAME %s' % e['label'])
    print(desc, '| res', res.group(1) if res else '?', '| r1', 'ok' if rc1 == 0 else 'FAIL', '|', v['status'], labels, '| pay', pay_s, '| shrink', round(sh[0]['mean_mm'], 4), '->', round(sh[-1]['mean_mm'], 4), '| PROBLEMS ' + '; '.join(problems) if problems else '')
    sys.stdout.flush()
