"""Reference figures for the MUKCa panda_6 two-socket data (see README.md beside this file).

Self-contained (numpy only). Run from the project root:

    python tests/data/mukca_panda6/reference.py

For each placement (front, left, right) and each model it computes the ball centre for every
row of hole_0.csv / hole_1.csv by forward kinematics from the URDF joint origins
(panda_link0 -> ... -> panda_hand_tcp -> ball_link), as MUKCa's calibrate_fk.utils.evaluate_model
does (yourdfpy get_transform(base_link, "ball_link")), and prints

  n0, n1     rows in hole_0.csv / hole_1.csv
  rms        sqrt(sum over both sockets of |p - mean_of_its_socket|^2 / (n0 + n1))    [mm]
             (= MUKCa's "std_dev_fk", their consistency figure)
  mae        mean over both sockets of |p - mean_of_its_socket|                          [mm]
             (= MUKCa's "mean_absolute_error")
  dist       |mean_0 - mean_1|                                                           [mm]
  dist_err   | |mean_0 - mean_1| - 50 mm |                                               [mm]
             (= MUKCa's "distance_error", offset_distance = 0.05 m)

Models:
  nominal     ../../../robots/panda/panda.urdf (franka_description kinematics, no ball) plus
              MUKCa's nominal ball offset read from nominal.urdf (ball_joint, parent panda_hand_tcp)
  nominal*    nominal.urdf (MUKCa's urdf/panda.urdf; same arm joints as robots/panda/panda.urdf)
  calibrated  calibrated.urdf (MUKCa's calibrated_urdf/panda_6/panda.urdf, trained on front only)
  nom+calball nominal arm with the calibrated ball offset (separates the ball's share)
"""
import os
import xml.etree.ElementTree as ET

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", "..", ".."))
PLACEMENTS = ("front", "left", "right")
SOCKET_DISTANCE = 0.05  # m, MUKCa default (ParameterOptimizer._offset_distance)
ARM = [f"panda_joint{i}" for i in range(1, 8)]
BASE, BALL = "panda_link0", "ball_link"


def rpy_matrix(r, p, y):
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx  # URDF: R = Rz(yaw) Ry(pitch) Rx(roll)


def axis_angle(axis, q):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(q) * kx + (1 - np.cos(q)) * kx @ kx


def load_joints(path):
    """{child_link: dict(name, type, parent, xyz, rpy, axis)} from a URDF."""
    joints = {}
    for j in ET.parse(path).getroot().findall("joint"):
        o = j.find("origin")
        a = j.find("axis")
        joints[j.find("child").get("link")] = dict(
            name=j.get("name"),
            type=j.get("type"),
            parent=j.find("parent").get("link"),
            xyz=np.array([float(v) for v in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()]),
            rpy=np.array([float(v) for v in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]),
            axis=np.array([float(v) for v in (a.get("xyz") if a is not None else "1 0 0").split()]),
        )
    return joints


def chain(joints, base, tip):
    out, link = [], tip
    while link != base:
        j = joints[link]
        out.append(j)
        link = j["parent"]
    return out[::-1]


def ball_positions(joints, q):
    """Ball centre in panda_link0 for each row of q (n x 7), metres."""
    ch = chain(joints, BASE, BALL)
    pts = np.empty((len(q), 3))
    for k, row in enumerate(q):
        qd = dict(zip(ARM, row))
        R, p = np.eye(3), np.zeros(3)
        for j in ch:
            Rj = rpy_matrix(*j["rpy"])
            p = p + R @ j["xyz"]
            R = R @ Rj
            if j["type"] in ("revolute", "continuous"):
                R = R @ axis_angle(j["axis"], qd[j["name"]])
            elif j["type"] == "prismatic":
                raise ValueError("prismatic joint on the ball chain")
        pts[k] = p
    return pts


def with_ball(joints, ball_joint):
    out = dict(joints)
    out[BALL] = dict(ball_joint)
    return out


def stats(p0, p1):
    d0 = np.linalg.norm(p0 - p0.mean(0), axis=1)
    d1 = np.linalg.norm(p1 - p1.mean(0), axis=1)
    d = np.concatenate([d0, d1])
    dist = np.linalg.norm(p0.mean(0) - p1.mean(0))
    return dict(
        n0=len(p0), n1=len(p1),
        rms=1e3 * np.sqrt(np.mean(d ** 2)),
        mae=1e3 * np.mean(d),
        dist=1e3 * dist,
        dist_err=1e3 * abs(dist - SOCKET_DISTANCE),
    )


def main():
    nominal_mukca = load_joints(os.path.join(HERE, "nominal.urdf"))
    calibrated = load_joints(os.path.join(HERE, "calibrated.urdf"))
    franka = load_joints(os.path.join(ROOT, "robots", "panda", "panda.urdf"))
    models = {
        "nominal": with_ball(franka, nominal_mukca[BALL]),
        "nominal*": nominal_mukca,
        "calibrated": calibrated,
        "nom+calball": with_ball(franka, calibrated[BALL]),
    }
    for name, jb in (("nominal", nominal_mukca[BALL]), ("calibrated", calibrated[BALL])):
        print(f"ball offset ({name}) in {jb['parent']}: xyz = {jb['xyz']} m")
    print(f"socket distance: {SOCKET_DISTANCE * 1e3:.1f} mm\n")
    hdr = f"{'placement':<10}{'model':<13}{'n0':>4}{'n1':>4}{'rms':>9}{'mae':>9}{'dist':>10}{'dist_err':>10}   (mm)"
    print(hdr)
    print("-" * len(hdr))
    for pl in PLACEMENTS:
        q0 = np.loadtxt(os.path.join(HERE, pl, "hole_0.csv"), delimiter=",", ndmin=2)
        q1 = np.loadtxt(os.path.join(HERE, pl, "hole_1.csv"), delimiter=",", ndmin=2)
        for name, joints in models.items():
            s = stats(ball_positions(joints, q0), ball_positions(joints, q1))
            print(f"{pl:<10}{name:<13}{s['n0']:>4}{s['n1']:>4}{s['rms']:>9.3f}{s['mae']:>9.3f}"
                  f"{s['dist']:>10.3f}{s['dist_err']:>10.3f}")
        print()


if __name__ == "__main__":
    main()
