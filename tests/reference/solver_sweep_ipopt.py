#!/usr/bin/env python3
"""IPOPT on the states of a solver sweep (tests/reference/solver_sweep.sh): every state whose
status is not 'converged', every state that took more than solver.max_iter iterations, and a
sample of the other converged ones; compares costs (1e-6 relative) and writes OUT/NAME.ipopt.json.
Usage (from the repository root): solver_sweep_ipopt.py NAME OUT [SAMPLE=200]"""
import sys, csv, json, random, collections, tomllib, os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy as np
import ipopt_compare as ic
name = sys.argv[1]; D = sys.argv[2]; sample = int(sys.argv[3]) if len(sys.argv) > 3 else 200
cfgp = f'configs/{name}.toml'
cfg = tomllib.load(open(cfgp, 'rb'))
ocp = ic.Ocp(cfg)
rows = list(csv.DictReader(open(f'{D}/{name}.out.csv')))
nx = ocp.nx
bad = [i for i, r in enumerate(rows) if r['status'] != 'converged']
maxit = int(cfg.get('solver', {}).get('max_iter', 100))
retried = [i for i, r in enumerate(rows) if r['status'] == 'converged' and int(r['iterations']) > maxit]
conv = [i for i, r in enumerate(rows) if r['status'] == 'converged' and int(r['iterations']) <= maxit]
samp = sorted(random.Random(5).sample(conv, min(sample, len(conv))))
out = {'name': name, 'counts': dict(collections.Counter(r['status'] for r in rows)), 'bad': [], 'sample': [], 'retried': []}
def run(i):
    r = rows[i]
    x = np.array([float(r[f'x{k+1}']) for k in range(nx)])
    w0 = ocp.initial_guess(x)
    res = ocp.solver(x0=w0, p=x, lbx=ocp.lbw, ubx=ocp.ubw, lbg=ocp.lbg, ubg=ocp.ubg)
    st = ocp.solver.stats()
    return {'i': i, 'x': x.tolist(), 'status': r['status'], 'cost_ours': float(r['cost']),
            'ipopt_ok': bool(st['success']), 'ipopt_status': st['return_status'],
            'cost_ipopt': float(res['f']), 'u_ours': float(r['u1']), 'u_ipopt': float(np.array(res['x']).ravel()[0])}
for i in bad: out['bad'].append(run(i))
for i in samp: out['sample'].append(run(i))
for i in retried: out['retried'].append(run(i))
def summ(lst):
    c = collections.Counter((d['status'], d['ipopt_status']) for d in lst)
    return {f'{a}|{b}': n for (a, b), n in c.items()}
out['bad_summary'] = summ(out['bad'])
s = out['sample']
both = [d for d in s if d['ipopt_ok']]
tol = lambda d: 1e-6 * max(1.0, abs(d['cost_ipopt']))
def cmp(s):
  both = [d for d in s if d['ipopt_ok']]
  return {'n': len(s), 'ipopt_ok': len(both),
  'same': sum(abs(d['cost_ours'] - d['cost_ipopt']) <= tol(d) for d in both),
  'ours_lower': sum(d['cost_ours'] < d['cost_ipopt'] - tol(d) for d in both),
  'ours_higher': sum(d['cost_ours'] > d['cost_ipopt'] + tol(d) for d in both),
  'max_rel_higher': max([(d['cost_ours'] - d['cost_ipopt']) / max(1, abs(d['cost_ipopt'])) for d in both] + [0])}
out['retried_summary'] = cmp(out['retried'])
out['sample_summary'] = {'n': len(s), 'ipopt_ok': len(both),
  'same': sum(abs(d['cost_ours'] - d['cost_ipopt']) <= tol(d) for d in both),
  'ours_lower': sum(d['cost_ours'] < d['cost_ipopt'] - tol(d) for d in both),
  'ours_higher': sum(d['cost_ours'] > d['cost_ipopt'] + tol(d) for d in both),
  'max_rel_higher': max([(d['cost_ours'] - d['cost_ipopt']) / max(1, abs(d['cost_ipopt'])) for d in both] + [0])}
bb = [d for d in out['bad'] if d['ipopt_ok'] and d['status'] == 'soft']
out['soft_vs_ipopt'] = len(bb)
json.dump(out, open(f'{D}/{name}.ipopt.json', 'w'), indent=1)
print(name, out['counts'], 'bad:', out['bad_summary'], 'sample:', out['sample_summary'], 'retried:', out['retried_summary'])
