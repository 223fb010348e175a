#!/usr/bin/env python3
# The consistency check of bench/results/2026-12-02-icp-sandwich-covariance.md: for each pair of consecutive
# frames, the centre's relative-motion error against ground truth tested against the two frames' covariances.
# Usage: 2026-12-02-icp-sandwich-nees.py RUN_DIR INPUT_DIR STDERR_OF_THE_RUN (a run of the measuring diff with
# VOF_SW=1 VOF_NOCOV=1, its stderr holding one "SW" line per frame: timestamp, inliers, then 3x3 covariances).
import sys, math, bisect
run, inp, err = sys.argv[1:4]
def load(p):
    out = []
    for l in open(p):
        if l.startswith('#') or not l.strip(): continue
        v = [float(x) for x in l.split()]
        out.append((v[0], v[1:4], v[4:8]))
    return out
def R(q):
    x, y, z, w = q
    return [[1-2*(y*y+z*z), 2*(x*y-z*w), 2*(x*z+y*w)], [2*(x*y+z*w), 1-2*(x*x+z*z), 2*(y*z-x*w)], [2*(x*z-y*w), 2*(y*z+x*w), 1-2*(x*x+y*y)]]
def mv(M, v): return [sum(M[i][j]*v[j] for j in range(3)) for i in range(3)]
def mt(M): return [[M[j][i] for j in range(3)] for i in range(3)]
def sub(a, b): return [a[i]-b[i] for i in range(3)]
def inv3(m):
    a,b,c,d,e,f,g,h,i = m[0][0],m[0][1],m[0][2],m[1][0],m[1][1],m[1][2],m[2][0],m[2][1],m[2][2]
    det = a*(e*i-f*h)-b*(d*i-f*g)+c*(d*h-e*g)
    if abs(det) < 1e-30: return None
    return [[(e*i-f*h)/det, (c*h-b*i)/det, (b*f-c*e)/det], [(f*g-d*i)/det, (a*i-c*g)/det, (c*d-a*f)/det], [(d*h-e*g)/det, (b*g-a*h)/det, (a*e-b*d)/det]]
est = load(run + '/trajectory.txt')
gt = load(inp + '/groundtruth.txt')
gts = [g[0] for g in gt]
def gtat(t):
    k = bisect.bisect_left(gts, t)
    c = [j for j in (k-1, k) if 0 <= j < len(gt)]
    j = min(c, key=lambda j: abs(gts[j]-t))
    return gt[j] if abs(gts[j]-t) < 0.02 else None
cov = {}
for l in open(err):
    if not l.startswith('SW '): continue
    v = l.split()
    t = float(v[1]); nums = [float(x) for x in v[3:]]
    cov[round(t, 4)] = [[[nums[9*k+3*i+j] for j in range(3)] for i in range(3)] for k in range(len(nums)//9)]
names = ['joint', 'T8', 'T16', 'T32', 'T64']
stats = {n: [] for n in names}; e2s = []; tr = {n: [] for n in names}
for a, b in zip(est, est[1:]):
    ca, cb = cov.get(round(a[0], 4)), cov.get(round(b[0], 4))
    ga, gb = gtat(a[0]), gtat(b[0])
    if not (ca and cb and ga and gb): continue
    Ra, Ga = R(a[2]), R(ga[2])
    de = mv(mt(Ra), sub(b[1], a[1])); dg = mv(mt(Ga), sub(gb[1], ga[1]))
    e = mv(Ra, sub(de, dg))  # world frame (estimate's)
    e2s.append(sum(x*x for x in e))
    for k, n in enumerate(names):
        S = [[ca[k][i][j] + cb[k][i][j] for j in range(3)] for i in range(3)]
        if S[0][0] <= 0: continue
        Si = inv3(S)
        if not Si: continue
        stats[n].append(sum(e[i]*mv(Si, e)[i] for i in range(3)))
        tr[n].append(S[0][0]+S[1][1]+S[2][2])
def med(x): x = sorted(x); return x[len(x)//2] if x else float('nan')
print('%s pairs %d rms_err_mm %.2f' % (run.split('/')[-1], len(e2s), 1000*math.sqrt(sum(e2s)/max(1,len(e2s)))), end='')
for n in names:
    s = stats[n]
    if s: print(' | %s nees_med %.1f scale %.2f' % (n, med(s), math.sqrt(sum(e2s)/len(e2s) / (sum(tr[n])/len(tr[n])))), end='')
print()
