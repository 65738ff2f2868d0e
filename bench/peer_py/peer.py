#!/usr/bin/env python3
"""Bullet (pybullet) and MuJoCo on a scene exported by `rigidsim export`.

Reads the bodies file (README.md, "rigidsim export"), builds the very same
bodies in one engine, steps it and writes

- a trajectory in rigidsim's `trajectory.csv` format (a probe run, nothing
  timed), which `yardstick` measures for every engine alike, and
- a JSON record of the timed runs (`--reps` fresh runs, only the engine's
  step call timed): wall seconds, the worst frame of `--frame` simulated
  seconds, the engine version and the coefficient mapping used.

Frames. Each engine's body frame is the body's principal frame at its centre
of mass: a part vertex v (rigidsim's body frame) becomes Rpᵀ v, the engine's
orientation is q·Rp, and the inertia is the diagonal of principal moments;
the trajectory is written back in rigidsim's body frame (q = q_engine·Rpᵀ).

Coefficients. rigidsim combines a pair's coefficients with the scene's rule;
each engine combines its own way, so each body gets the value that makes
every pair that can touch come out at rigidsim's coefficient (`mapping`):
Bullet multiplies (solved in logarithms over the pairs; a body whose
coefficient is 0 gets 0); MuJoCo takes the geom of higher `priority`, the
larger friction between equals, and explicit `<pair>`s where one priority
order cannot give both friction and restitution.

Usage: peer.py ENGINE CONFIG BODIES --duration S --trajectory CSV --record JSON
       [--sample-every N] [--frame S] [--reps N]
ENGINE CONFIG: bullet dantzig | bullet default | mujoco default | mujoco hard.
"""
import argparse
import json
import math
import os
import sys
import tempfile
import time

import numpy as np

# Bullet's user manual: moving objects are assumed to be 0.05 to 10 units in
# size. The nuts and bolts are 4 cm and the cubes 10 cm, so Bullet runs the
# world scaled by 10 (lengths, velocities and gravity; masses unchanged,
# inertia by 100) and every state is scaled back before it is written.
BULLET_SCALE = 10.0

def qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def qconj(q):
    return (q[0], -q[1], -q[2], -q[3])


def qmat(q):
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def qnorm(q):
    n = math.sqrt(sum(c * c for c in q))
    return tuple(c / n for c in q)


def touching_pairs(scene):
    """Object pairs (i <= j) that can touch: at least one body dynamic, and a
    pair of one object with itself only where it has two bodies."""
    count, dyn = {}, {}
    for b in scene["bodies"]:
        o = b["object"]
        count[o] = count.get(o, 0) + 1
        dyn[o] = dyn.get(o, 0) + (b["kind"] == "dynamic")
    objs = sorted(count)
    pairs = []
    for a in objs:
        for b in objs:
            if b < a:
                continue
            if a == b and (count[a] < 2 or dyn[a] == 0):
                continue
            if a != b and dyn[a] + dyn[b] == 0:
                continue
            pairs.append((a, b))
    return pairs


def combine(rule, a, b):
    """rigidsim's combine rule (`restitution_rule`, `friction_rule`)."""
    return {"min": min(a, b), "max": max(a, b), "mean": 0.5 * (a + b), "product": a * b}[rule]


def object_coefficients(scene, key):
    out = {}
    for b in scene["bodies"]:
        out[b["object"]] = b[key]
    return out


def product_mapping(scene, key, rule):
    """Per-object values whose products give every touching pair rigidsim's
    combined coefficient: log f_a + log f_b = log c_ab, least squares; an
    object whose every pair wants 0 gets 0. Returns (values, worst error)."""
    c = object_coefficients(scene, key)
    pairs = touching_pairs(scene)
    want = {p: combine(rule, c[p[0]], c[p[1]]) for p in pairs}
    zero = {o for o in c if all(want[p] == 0 for p in pairs if o in p)}
    objs = [o for o in sorted(c) if o not in zero]
    idx = {o: k for k, o in enumerate(objs)}
    rows, rhs = [], []
    for p in pairs:
        if p[0] in zero or p[1] in zero:
            continue
        r = np.zeros(len(objs))
        r[idx[p[0]]] += 1
        r[idx[p[1]]] += 1
        rows.append(r)
        rhs.append(math.log(want[p]) if want[p] > 0 else -50.0)
    values = {o: 0.0 for o in zero}
    if rows:
        sol = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]
        for o in objs:
            values[o] = math.exp(sol[idx[o]])
    for o in objs:
        values.setdefault(o, math.sqrt(c[o]))
    worst = max([abs(values[a] * values[b] - want[(a, b)]) for a, b in pairs] + [0.0])
    return values, worst, {f"{a}-{b}": want[(a, b)] for a, b in pairs}


def read_scene(path):
    with open(path) as f:
        scene = json.load(f)
    if scene.get("format") != 1:
        sys.exit(f"peer: {path}: export format {scene.get('format')} (this peer reads 1)")
    for b in scene["bodies"]:
        if b["kind"] == "driven":
            sys.exit(f"peer: {path}: body {b['index']} is driven; this peer has no driven bodies")
    return scene


class Writer:
    """Rows of rigidsim's trajectory.csv; a body below fall_z keeps the state
    it had in the step that found it there."""

    HEADER = "time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz\n"

    def __init__(self, path):
        self.f = open(path, "w") if path else None
        if self.f:
            self.f.write(self.HEADER)

    def write(self, t, states):
        if not self.f:
            return
        lines = []
        for i, (x, q, v, w) in enumerate(states):
            nums = (t, *x, *q, *v, *w)
            lines.append(f"{float(nums[0])!r},{i}," + ",".join(repr(float(c)) for c in nums[1:]) + "\n")
        self.f.write("".join(lines))

    def close(self):
        if self.f:
            self.f.close()


# ---------------------------------------------------------------------------
# Bullet


class Bullet:
    def __init__(self, scene, config, objdir):
        import pybullet as p

        self.p = p
        self.c = p.connect(p.DIRECT)
        S = BULLET_SCALE
        w = scene["world"]
        p.resetSimulation(physicsClientId=self.c)
        params = dict(fixedTimeStep=w["dt"], numSubSteps=0, deterministicOverlappingPairs=1)
        if config == "dantzig":
            params["constraintSolverType"] = p.CONSTRAINT_SOLVER_LCP_DANTZIG
        p.setPhysicsEngineParameter(physicsClientId=self.c, **params)
        p.setGravity(*[S * g for g in w["gravity"]], physicsClientId=self.c)
        rule_e, rule_f = w["restitution_rule"], w["friction_rule"]
        self.rest, self.rest_err, _ = product_mapping(scene, "restitution", rule_e)
        self.fric, self.fric_err, _ = product_mapping(scene, "friction", rule_f)
        # One compound per body, each part the convex hull of its vertices
        # (an OBJ file a part: pybullet's compound shapes take meshes by file).
        shapes = {}
        self.rp, self.ids, self.dynamic = [], [], []
        for b in scene["bodies"]:
            o = scene["objects"][b["object"]]
            rp = tuple(b["principal_rotation"])
            r = qmat(rp)
            key = (b["object"], rp)
            if key not in shapes:
                files = []
                for k, part in enumerate(o["parts"]):
                    name = os.path.join(objdir, f"o{b['object']}_{len(shapes)}_p{k}.obj")
                    with open(name, "w") as f:
                        for v in part["vertices"]:
                            q = [float(c) for c in S * (r.T @ np.array(v))]
                            f.write("v %r %r %r\n" % (q[0], q[1], q[2]))
                        for face in part["faces"]:
                            for t in range(1, len(face) - 1):
                                f.write("f %d %d %d\n" % (face[0] + 1, face[t] + 1, face[t + 1] + 1))
                    files.append(name)
                shapes[key] = p.createCollisionShapeArray(
                    [p.GEOM_MESH] * len(files), fileNames=files, physicsClientId=self.c
                )
            st = b["initial"]
            qe = qmul(tuple(st["orientation"]), rp)
            dyn = b["kind"] == "dynamic"
            bid = p.createMultiBody(
                baseMass=b["mass"] if dyn else 0.0,
                baseCollisionShapeIndex=shapes[key],
                basePosition=[S * x for x in st["position"]],
                baseOrientation=[qe[1], qe[2], qe[3], qe[0]],
                physicsClientId=self.c,
            )
            dyn_args = dict(
                restitution=self.rest[b["object"]],
                lateralFriction=self.fric[b["object"]],
                rollingFriction=0.0,
                spinningFriction=0.0,
                linearDamping=0.0,
                angularDamping=0.0,
            )
            if dyn:
                dyn_args["localInertiaDiagonal"] = [S * S * m for m in b["principal_moments"]]
            p.changeDynamics(bid, -1, physicsClientId=self.c, **dyn_args)
            if dyn:
                p.resetBaseVelocity(
                    bid,
                    [S * x for x in st["velocity"]],
                    st["angular_velocity"],
                    physicsClientId=self.c,
                )
            self.ids.append(bid)
            self.rp.append(rp)
            self.dynamic.append(dyn)
        self.fall_z = w["fall_z"] if w["fall_z"] is not None else -math.inf
        self.frozen = [None] * len(self.ids)

    def version(self):
        return "pybullet " + _dist_version("pybullet")

    def mapping(self):
        return {
            "restitution": {str(k): v for k, v in self.rest.items()},
            "friction": {str(k): v for k, v in self.fric.items()},
            "worst_pair_error": max(self.rest_err, self.fric_err),
            "world_scale": BULLET_SCALE,
        }

    def step(self):
        self.p.stepSimulation(physicsClientId=self.c)

    def read(self):
        p, S, out = self.p, BULLET_SCALE, []
        for i, bid in enumerate(self.ids):
            if self.frozen[i] is not None:
                out.append(self.frozen[i])
                continue
            x, qe = p.getBasePositionAndOrientation(bid, physicsClientId=self.c)
            v, w = p.getBaseVelocity(bid, physicsClientId=self.c)
            q = qnorm(qmul((qe[3], qe[0], qe[1], qe[2]), qconj(self.rp[i])))
            s = ([c / S for c in x], q, [c / S for c in v], list(w))
            if self.dynamic[i] and s[0][2] < self.fall_z:
                self.frozen[i] = s
                p.removeBody(bid, physicsClientId=self.c)
            out.append(s)
        return out

    def close(self):
        self.p.disconnect(physicsClientId=self.c)


# ---------------------------------------------------------------------------
# MuJoCo


def mujoco_restitution_solref(e, timeconst):
    """solref (timeconst, dampratio) of the contact spring-damper whose
    rebound over one half oscillation keeps the fraction e of the approach
    speed: e = exp(−ζπ/√(1−ζ²)), so ζ = −ln e / √(π² + ln² e); e = 0 gives
    ζ = 1 (critical damping, no rebound)."""
    if e <= 0:
        return (timeconst, 1.0)
    le = math.log(e)
    return (timeconst, -le / math.sqrt(math.pi**2 + le * le))


class MuJoCo:
    def __init__(self, scene, config, dampratio=None):
        """dampratio: one damping ratio for every contact instead of the one
        mapped from restitution (the fallback after a divergence)."""
        import mujoco

        self.mj = mujoco
        w = scene["world"]
        dt = w["dt"]
        # The stiffest contact MuJoCo's documentation allows: timeconst at
        # least twice the step.
        tc = 2.0 * dt
        rule_e, rule_f = w["restitution_rule"], w["friction_rule"]
        ce = object_coefficients(scene, "restitution")
        cf = object_coefficients(scene, "friction")
        pairs = touching_pairs(scene)
        # priority: the object of lower friction wins (min rule); ties by
        # lower restitution. A pair whose winner has not both of rigidsim's
        # combined coefficients gets explicit <pair>s (and its geoms no
        # dynamic contacts between those objects, through <exclude> or
        # contype bits below).
        order = sorted(ce, key=lambda o: (cf[o], ce[o]))
        prio = {o: len(order) - k for k, o in enumerate(order)}
        if rule_e != "min" or rule_f != "min":
            sys.exit("peer: the MuJoCo mapping is written for rigidsim's min rule")
        explicit = []
        for a, b in pairs:
            want = (combine(rule_f, cf[a], cf[b]), combine(rule_e, ce[a], ce[b]))
            win = a if prio[a] >= prio[b] else b
            got = (cf[win], ce[win])
            if a != b and prio[a] == prio[b]:
                got = (max(cf[a], cf[b]), ce[a] if ce[a] == ce[b] else None)
            if got != want:
                explicit.append((a, b, want))
        self.explicit = [(a, b) for a, b, _ in explicit]
        opt = f'timestep="{dt!r}" gravity="{" ".join(repr(g) for g in w["gravity"])}"'
        if config == "hard":
            # MuJoCo's documentation for hard, non-slipping contacts:
            # elliptic friction cones, impratio raised, noslip iterations.
            opt += ' cone="elliptic" impratio="10" noslip_iterations="10"'
        xml = [f'<mujoco><compiler angle="radian" boundmass="0" boundinertia="0"/><option {opt}/>']
        xml.append("<default><geom condim=\"3\"/></default><asset>")
        rp_of = {}
        for b in scene["bodies"]:
            rp_of.setdefault(b["object"], tuple(b["principal_rotation"]))
        for oi, rp in rp_of.items():
            r = qmat(rp)
            for k, part in enumerate(scene["objects"][oi]["parts"]):
                vs = " ".join(
                    " ".join(repr(float(c)) for c in (r.T @ np.array(v))) for v in part["vertices"]
                )
                xml.append(f'<mesh name="m{oi}_{k}" vertex="{vs}" inertia="convex"/>')
        xml.append("</asset><worldbody>")
        fixed_objs = {b["object"] for b in scene["bodies"] if b["kind"] != "dynamic"}
        self.dynamic, self.rp, self.names = [], [], []
        geoms = {}  # object -> geom names
        for b in scene["bodies"]:
            oi = b["object"]
            rp = rp_of[oi]
            if tuple(b["principal_rotation"]) != rp:
                sys.exit("peer: bodies of one object with different principal frames")
            st = b["initial"]
            qe = qmul(tuple(st["orientation"]), rp)
            dyn = b["kind"] == "dynamic"
            name = f"b{b['index']}"
            ref = mujoco_restitution_solref(ce[oi], tc) if dampratio is None else (tc, dampratio)
            gs = []
            body = [
                f'<body name="{name}" pos="{" ".join(map(repr, st["position"]))}" '
                f'quat="{" ".join(map(repr, qe))}">'
            ]
            if dyn:
                body.append(f'<freejoint name="j{b["index"]}"/>')
                pm = b["principal_moments"]
                body.append(
                    f'<inertial pos="0 0 0" mass="{b["mass"]!r}" diaginertia="{pm[0]!r} {pm[1]!r} {pm[2]!r}"/>'
                )
            for k in range(len(scene["objects"][oi]["parts"])):
                g = f"g{b['index']}_{k}"
                gs.append(g)
                body.append(
                    f'<geom name="{g}" type="mesh" mesh="m{oi}_{k}" mass="0" '
                    f'friction="{cf[oi]!r} 0 0" solref="{ref[0]!r} {ref[1]!r}" '
                    f'priority="{prio[oi]}"/>'
                )
            body.append("</body>")
            xml.extend(body)
            geoms.setdefault(oi, []).append((gs, dyn, name))
            self.dynamic.append(dyn)
            self.rp.append(rp)
            self.names.append(name)
        xml.append("</worldbody><contact>")
        for a, b, (mu, e) in explicit:
            if a == b:
                sys.exit("peer: an object's contacts with itself need no explicit pair")
            ref = mujoco_restitution_solref(e, tc) if dampratio is None else (tc, dampratio)
            for ga, da, na in geoms[a]:
                for gb, db, nb in geoms[b]:
                    if not (da or db):
                        continue
                    xml.append(f'<exclude body1="{na}" body2="{nb}"/>')
                    for x in ga:
                        for y in gb:
                            xml.append(
                                f'<pair geom1="{x}" geom2="{y}" condim="3" '
                                f'friction="{mu!r} {mu!r} 0 0 0" solref="{ref[0]!r} {ref[1]!r}"/>'
                            )
        xml.append("</contact></mujoco>")
        self.xml = "\n".join(xml)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        self.jadr, self.badr = [], []
        for i, name in enumerate(self.names):
            bid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)
            self.badr.append(bid)
            if self.dynamic[i]:
                j = self.model.body_jntadr[bid]
                self.jadr.append((self.model.jnt_qposadr[j], self.model.jnt_dofadr[j]))
                st = scene["bodies"][i]["initial"]
                qe = qmul(tuple(st["orientation"]), self.rp[i])
                self.data.qvel[self.jadr[-1][1] : self.jadr[-1][1] + 3] = st["velocity"]
                # a free joint's angular velocity is in the body frame
                self.data.qvel[self.jadr[-1][1] + 3 : self.jadr[-1][1] + 6] = (
                    qmat(qe).T @ np.array(st["angular_velocity"])
                )
            else:
                self.jadr.append(None)
        mujoco.mj_forward(self.model, self.data)
        self.fall_z = w["fall_z"] if w["fall_z"] is not None else -math.inf
        self.frozen = [None] * len(self.names)
        self.priority = prio
        self.tc = tc
        self.ce = ce
        self.dampratio = dampratio
        self.diverged_at = None
        self.time = 0.0

    def version(self):
        return "mujoco " + self.mj.__version__

    def mapping(self):
        return {
            "priority": {str(k): v for k, v in self.priority.items()},
            "solref": {
                str(k): list(mujoco_restitution_solref(e, self.tc))
                if self.dampratio is None
                else [self.tc, self.dampratio]
                for k, e in self.ce.items()
            },
            "explicit_pairs": [f"{a}-{b}" for a, b in self.explicit],
            "worst_pair_error": 0.0,
        }

    def step(self):
        self.mj.mj_step(self.model, self.data)
        self.time += self.model.opt.timestep
        # MuJoCo resets the state when accelerations blow up (mjWARN_BADQACC).
        if self.diverged_at is None and self.data.warning[self.mj.mjtWarning.mjWARN_BADQACC].number:
            self.diverged_at = self.time

    def read(self):
        out = []
        d = self.data
        for i in range(len(self.names)):
            if self.frozen[i] is not None:
                out.append(self.frozen[i])
                continue
            if self.jadr[i] is None:
                bid = self.badr[i]
                x, qe = list(d.xpos[bid]), tuple(d.xquat[bid])
                s = (x, qnorm(qmul(qe, qconj(self.rp[i]))), [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
            else:
                # The free joint's qpos, not xpos/xquat: those are computed
                # at the start of mj_step, one step behind its integration.
                adr, dof = self.jadr[i]
                x = list(d.qpos[adr : adr + 3])
                qe = tuple(d.qpos[adr + 3 : adr + 7])
                q = qnorm(qmul(qe, qconj(self.rp[i])))
                v = list(d.qvel[dof : dof + 3])
                w = list(qmat(qe) @ d.qvel[dof + 3 : dof + 6])
                s = (x, q, v, w)
                if x[2] < self.fall_z:
                    self.frozen[i] = s
            out.append(s)
        return out

    def close(self):
        pass


def _dist_version(name):
    try:
        from importlib.metadata import version

        return version(name)
    except Exception:
        return "unknown"


def make(engine, config, scene, objdir, fallback=None):
    if engine == "bullet":
        return Bullet(scene, config, objdir)
    return MuJoCo(scene, config, fallback)


def probe(a, scene, objdir, steps, dt, fallback=None):
    """The probe run: writes the trajectory; returns the engine's version,
    mapping and the time it diverged (None: it did not)."""
    e = make(a.engine, a.config, scene, objdir, fallback)
    w = Writer(a.trajectory)
    w.write(0.0, e.read())
    for k in range(1, steps + 1):
        e.step()
        states = e.read()
        if k % a.sample_every == 0 or k == steps:
            w.write(k * dt, states)
    w.close()
    out = (e.version(), e.mapping(), getattr(e, "diverged_at", None))
    e.close()
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("engine", choices=["bullet", "mujoco"])
    ap.add_argument("config", choices=["dantzig", "default", "hard"])
    ap.add_argument("bodies")
    ap.add_argument("--duration", type=float, required=True)
    ap.add_argument("--trajectory", required=True)
    ap.add_argument("--record", required=True)
    ap.add_argument("--sample-every", type=int, default=1, help="steps between trajectory rows")
    ap.add_argument("--frame", type=float, default=0.1, help="simulated seconds of a frame")
    ap.add_argument("--reps", type=int, default=1)
    a = ap.parse_args()
    if a.engine == "bullet" and a.config == "hard" or a.engine == "mujoco" and a.config == "dantzig":
        sys.exit(f"peer: no configuration {a.config} for {a.engine}")
    scene = read_scene(a.bodies)
    dt = scene["world"]["dt"]
    steps = max(0, math.ceil(a.duration / dt - 1e-9))
    frame_steps = max(1, round(a.frame / dt))
    objdir = tempfile.mkdtemp(prefix="peer-obj-")

    # Probe run: the trajectory, nothing timed. Where MuJoCo's contacts with
    # the damping mapped from restitution diverge (it then resets the state),
    # the run is made again with its default damping ratio 1 (no rebound),
    # and the record says so.
    fallback = None
    version, mapping, diverged = probe(a, scene, objdir, steps, dt)
    if diverged is not None:
        fallback = 1.0
        version, mapping, again = probe(a, scene, objdir, steps, dt, fallback)
        mapping["diverged_with_mapped_restitution_at_s"] = diverged
        mapping["diverged_again_at_s"] = again

    # Timed runs: fresh engines, only the step call timed.
    walls, worsts = [], []
    for _ in range(a.reps):
        e = make(a.engine, a.config, scene, objdir, fallback)
        total, frame, worst = 0.0, 0.0, 0.0
        for k in range(1, steps + 1):
            t0 = time.perf_counter()
            e.step()
            s = time.perf_counter() - t0
            total += s
            frame += s
            if k % frame_steps == 0 or k == steps:
                worst = max(worst, frame)
                frame = 0.0
            if a.engine == "bullet" and k % frame_steps == 0:
                e.read()  # removes bodies below fall_z, as in the probe run
        e.close()
        walls.append(total)
        worsts.append(worst)
    rec = {
        "engine": f"{a.engine}_{a.config}",
        "version": version,
        "steps": steps,
        "dt": dt,
        "sim_time_s": steps * dt,
        "walls_s": walls,
        "worst_frames_s": worsts,
        "frame_interval_s": a.frame,
        "threads": 1,
        "mapping": mapping,
    }
    with open(a.record, "w") as f:
        json.dump(rec, f)


if __name__ == "__main__":
    main()
