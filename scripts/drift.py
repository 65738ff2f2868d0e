#!/usr/bin/env python3
"""Drift of linear momentum, angular momentum (about the origin) and kinetic
energy between the first and last rows of a run's trajectory.csv, for a scene
with no gravity and no fixed or driven body (scripts/crowd.sh's
zero_g_crowd), where all three have exact answers when restitution is 1 and
friction 0. Each drift is relative to its scale at t = 0 (sum of m|v|, of
|m r x v| + |I w|, and the energy). Masses and inertia come from
`rigidsim export`.

Usage: scripts/drift.py EXPORT.json TRAJECTORY.csv
Prints: momentum_drift angular_momentum_drift energy_drift (relative)."""
import csv
import json
import sys


def rotation(q):
    w, x, y, z = q
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]


def mat_vec(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


def transpose(m):
    return [[m[j][i] for j in range(3)] for i in range(3)]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def norm(v):
    return sum(x * x for x in v) ** 0.5


def totals(bodies, rows):
    """Linear momentum, angular momentum about the origin, kinetic energy,
    and the scales of the first two."""
    p, l, e, p_scale, l_scale = [0.0] * 3, [0.0] * 3, 0.0, 0.0, 0.0
    for row in rows:
        b = bodies[int(row["body"])]
        m, inertia = b["mass"], b["inertia"]
        r = [float(row[k]) for k in ("x", "y", "z")]
        v = [float(row[k]) for k in ("vx", "vy", "vz")]
        w = [float(row[k]) for k in ("wx", "wy", "wz")]
        rot = rotation([float(row[k]) for k in ("qw", "qx", "qy", "qz")])
        # I_world w = R I R^T w
        iw = mat_vec(rot, mat_vec(inertia, mat_vec(transpose(rot), w)))
        mv = [m * x for x in v]
        orbital = cross(r, mv)
        p = [a + c for a, c in zip(p, mv)]
        l = [a + c + d for a, c, d in zip(l, orbital, iw)]
        e += 0.5 * m * sum(x * x for x in v) + 0.5 * sum(a * c for a, c in zip(w, iw))
        p_scale += norm(mv)
        l_scale += norm(orbital) + norm(iw)
    return p, l, e, p_scale, l_scale


def main():
    export = json.load(open(sys.argv[1]))
    bodies = export["bodies"]
    if any(b["kind"] != "dynamic" for b in bodies):
        sys.exit("drift.py: every body must be dynamic")
    by_time = {}
    for row in csv.DictReader(open(sys.argv[2])):
        by_time.setdefault(float(row["time"]), []).append(row)
    first, last = by_time[min(by_time)], by_time[max(by_time)]
    if len(last) != len(bodies):
        sys.exit("drift.py: bodies missing from the last row (fallen?)")
    p0, l0, e0, ps, ls = totals(bodies, first)
    p1, l1, e1, _, _ = totals(bodies, last)
    dp = norm([a - b for a, b in zip(p1, p0)]) / max(ps, 1e-300)
    dl = norm([a - b for a, b in zip(l1, l0)]) / max(ls, 1e-300)
    print(f"{dp:.2e} {dl:.2e} {(e1 - e0) / e0:.2e}")


main()
