"""Simulated trials of the program filters: programs of mixed joint and Cartesian targets for a robot,
and their execution on a truth robot through the controller's nominal model (target -> nominal
inverse kinematics in the target's configuration -> joints -> the truth's tool)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gecgen.deliver.programs.core import Format, Frames, Number, Program, Target, frame_of
from gecgen.deliver.programs.kinematics import Arm, inverse, seed_grid, wrapped
from gecgen.model.kinematics import constant


def postures(arm: Arm, n: int, rng: np.random.Generator, margin_deg: float = 8.0) -> np.ndarray:
    """n joint postures (n, 6) rad drawn inside the limits (less a margin, and within +-180 deg), away
    from the wrist, elbow and shoulder singularities: what a programmer teaches."""
    lo, hi = arm.limits()
    m = np.deg2rad(margin_deg)
    lo, hi = np.maximum(lo + m, -np.pi + m), np.minimum(hi - m, np.pi - m)
    found = []
    while len(found) < n:
        q = rng.uniform(lo, hi, (4 * n, 6))
        ahead = arm.ahead(q)
        keep = ((np.abs(np.sin(q[:, 4])) > np.sin(np.deg2rad(15))) & (np.abs(ahead) > 0.25)
                & (np.abs(wrapped(arm.chain(q)[:, 2] - arm.stretch)) > np.deg2rad(15)) & (arm.fk(q)[:, 2, 3] > 0.2))
        found.extend(q[keep])
    return np.array(found[:n])


@dataclass(frozen=True)
class Executed:
    """Where the truth robot put the tool point for each target (N, 3) m, and where it was meant to go
    (N, 3) m; reached (N,) the targets the controller could solve."""

    placed: np.ndarray
    intended: np.ndarray
    reached: np.ndarray

    def errors_mm(self) -> np.ndarray:
        return 1e3 * np.linalg.norm(self.placed - self.intended, axis=1)[self.reached]


def _controller_joints(fmt: Format, program: Program, frames: Frames, arm: Arm):
    """Each target's joints (rad) as the controller solves them, its tool (4, 4) and base (4, 4)."""
    config = fmt.config(arm) if fmt.config else None
    seeds, previous, out = seed_grid(arm, config), None, []
    scale = np.pi / 180.0 if fmt.joint_unit == "deg" else 1.0
    for t in program.targets:
        if t.note is not None:  # a motion without a target of its own: not part of the comparison
            out.append((None, np.eye(4), np.eye(4)))
            continue
        if t.kind == "joint":
            q, tool, base = np.array(t.values) * scale, np.eye(4), np.eye(4)
        else:
            tool = frame_of(t.tool, program, frames, "tools", fmt, t)
            base = frame_of(t.base, program, frames, "bases", fmt, t)
            goal = base @ fmt.pose(t.values) @ np.linalg.inv(tool)
            q = inverse(arm, goal, seeds, config, t.config, near=previous if config is None else None)
        out.append((q, tool, base))
        previous = q if q is not None else previous
    return out


def execute(fmt: Format, original: Program, run: Program, frames: Frames, arm: Arm, truth_robot, truth) -> Executed:
    """Run `run` (the original or its filtered copy, target for target) on the truth robot and compare
    the tool point of every target with where the original meant it to be (joint targets: the
    nominal model's tool at the original joints)."""
    from gecgen.simulate import true_tool_points

    meant = _controller_joints(fmt, original, frames, arm)
    done = _controller_joints(fmt, run, frames, arm)
    robot_tool = constant(arm.robot.tips()[0][1])
    reached = np.array([a[0] is not None and b[0] is not None for a, b in zip(meant, done)])
    intended, placed = np.zeros((len(meant), 3)), np.zeros((len(meant), 3))
    for k, ((q0, tool, _), (q1, _, _)) in enumerate(zip(meant, done)):
        if not reached[k]:
            continue
        intended[k] = (arm.fk(q0)[0] @ tool)[:3, 3]
        point = (np.linalg.inv(robot_tool) @ arm.flange @ tool)[:3, 3]
        placed[k] = true_tool_points(truth_robot, truth, q1[None], np.zeros(1), np.zeros(3), point[None])[0][0]
    return Executed(placed, intended, reached)


# -- programs ------------------------------------------------------------------------------------

def pose_values(fmt: Format, T: np.ndarray, units: tuple[str, ...]) -> list[float]:
    """The numbers of pose T (4, 4, m) in the format's convention (its own choice among equivalent angles)."""
    blank = Target("", Path(""), 0, "pose", tuple(Number(0, 0, "0", u) for u in units))
    return fmt.numbers(T, blank)


def _krl_aggregate(keys, values, digits) -> str:
    return ",".join(f"{k} {v:.{d}f}" for k, v, d in zip(keys, values, digits))


def krl_program(name: str, arm: Arm, q: np.ndarray, kinds: list[str], tool: tuple[int, np.ndarray],
                base: tuple[int, np.ndarray]) -> tuple[str, str]:
    """A KRL program (.src text, .dat text) visiting postures q (N, 6) rad: kinds[k] one of
    "axis" (an E6AXIS in the .dat), "pos" (an E6POS with its FDAT), "inline-axis", "inline-pos"
    (written in the motion); Cartesian targets in tool[0] (flange -> TCP tool[1]) and base base[0]
    (robot base -> base[1])."""
    from gecgen.deliver.programs import kuka

    config = kuka.config(arm)
    src = [f"&ACCESS RVP", "&REL 1", f"DEF {name}( )", ";FOLD INI", "  BAS (#INITMOV,0 )", ";ENDFOLD (INI)",
           f"$TOOL=TOOL_DATA[{tool[0]}]", f"$BASE=BASE_DATA[{base[0]}]", "$VEL.CP=0.25 ; m/s", ""]
    dat = ["&ACCESS RVP", "&REL 1", f"DEFDAT  {name}", ";FOLD EXTERNAL DECLARATIONS;%{PE}%MKUKATPBASIS,%CEXT,%P",
           ";ENDFOLD (EXTERNAL DECLARATIONS)"]
    for k, (qk, kind) in enumerate(zip(q, kinds)):
        deg = np.rad2deg(qk)
        P = np.linalg.inv(base[1]) @ arm.fk(qk)[0] @ tool[1]
        xyzabc = pose_values(kuka.FORMAT, P, ("mm",) * 3 + ("deg",) * 3)
        s, t = config(qk[None])[0]
        point = f"P{k + 1}"
        if kind == "axis":
            dat.append(f"DECL E6AXIS X{point}={{{_krl_aggregate(kuka.JOINT_KEYS, deg, [5] * 6)},E1 0.0,E2 0.0,"
                       f"E3 0.0,E4 0.0,E5 0.0,E6 0.0}}")
            src.append(f"PTP X{point} C_PTP ; taught joint target")
        elif kind == "pos":
            dat.append(f"DECL E6POS X{point}={{{_krl_aggregate(kuka.POSE_KEYS, xyzabc, [5] * 6)},S {s},T {t},"
                       f"E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}")
            dat.append(f"DECL FDAT F{point}={{TOOL_NO {tool[0]},BASE_NO {base[0]},IPO_FRAME #BASE,POINT2[] \" \"}}")
            src.append(f"{'LIN' if k % 3 else 'PTP'} X{point} C_DIS ; taught pose")
        elif kind == "inline-axis":
            src.append(f"PTP {{{_krl_aggregate(kuka.JOINT_KEYS, deg, [2] * 6)}}}")
        else:
            src.append(f"PTP {{{_krl_aggregate(kuka.POSE_KEYS, xyzabc, [2] * 6)},S 'B{s:03b}',T 'B{t:06b}'}} C_PTP")
        if k % 10 == 9:
            src.append("WAIT SEC 0.5 ; let the part settle")
    src += ["", "END", ""]
    dat += ["ENDDAT", ""]
    return "\r\n".join(src), "\r\n".join(dat)


def ur_program(name: str, arm: Arm, q: np.ndarray, kinds: list[str], tcp: np.ndarray) -> str:
    """A UR script visiting postures q (N, 6) rad: kinds[k] one of "movej" (a joint list), "movel",
    "movep", "movej-pose" (a pose p[...]) and "variable" (a pose assigned first, then moved to), with
    the TCP tcp (4, 4, flange -> TCP) set by set_tcp."""
    from gecgen.deliver.programs import ur

    units = ("m",) * 3 + ("rad",) * 3
    lines = [f"def {name}():", f"  set_tcp(p[{', '.join(f'{v:.4f}' for v in pose_values(ur.FORMAT, tcp, units))}])",
             "  set_payload(2.5)", "  # a pick-and-place cycle"]
    for k, (qk, kind) in enumerate(zip(q, kinds)):
        p = ", ".join(f"{v:.6f}" for v in pose_values(ur.FORMAT, arm.fk(qk)[0] @ tcp, units))
        if kind == "movej":
            lines.append(f"  movej([{', '.join(f'{v:.5f}' for v in qk)}], a=1.4, v=1.05)")
        elif kind == "variable":
            lines += [f"  global Waypoint_{k + 1}_p=p[{p}]", f"  movel(Waypoint_{k + 1}_p, a=1.2, v=0.25)"]
        elif kind == "movej-pose":
            lines.append(f"  movej(p[{p}], a=1.4, v=1.05, r=0.05)")
        else:
            lines.append(f"  {kind}(p[{p}], a=1.2, v=0.25{', r=0.02' if kind == 'movep' else ''})")
        if k % 10 == 9:
            lines.append("  sleep(0.5)")
    return "\n".join(lines + ["end", f"{name}()", ""])


def rapid_program(name: str, arm: Arm, q: np.ndarray, kinds: list[str], tool: np.ndarray,
                  wobj: np.ndarray) -> str:
    """A RAPID module visiting postures q (N, 6) rad: kinds[k] one of "jointtarget", "robtarget" (declared)
    or "inline" (a robtarget written in the move); robtargets in tooldata tGripper (flange -> TCP `tool`)
    and wobjdata wobjTable (robot base -> `wobj`), both declared in the module."""
    from gecgen.deliver.programs import abb

    config = abb.config(arm)
    units = ("mm",) * 3 + ("1",) * 4

    def group(values, digits):
        return ",".join(f"{v:.{digits}f}" for v in values)

    t, w = pose_values(abb.FORMAT, tool, units), pose_values(abb.FORMAT, wobj, units)
    head = [f"MODULE {name}", "    ! cell program: taught on the pendant, edited offline",
            f"    PERS tooldata tGripper:=[TRUE,[[{group(t[:3], 1)}],[{group(t[3:], 6)}]],"
            f"[12.5,[0,0,120],[1,0,0,0],0,0,0]];",
            f"    TASK PERS wobjdata wobjTable:=[FALSE,TRUE,\"\",[[{group(w[:3], 1)}],[{group(w[3:], 6)}]],"
            f"[[0,0,0],[1,0,0,0]]];",
            "    CONST speeddata vFast:=[1500,500,5000,1000];"]
    body = ["", "    PROC main()", "        ConfJ\\On;", "        ConfL\\On;"]
    for k, (qk, kind) in enumerate(zip(q, kinds)):
        deg = np.rad2deg(qk)
        P = np.linalg.inv(wobj) @ arm.fk(qk)[0] @ tool
        v = pose_values(abb.FORMAT, P, units)
        cf = config(qk[None])[0]
        literal = (f"[[{group(v[:3], 2)}],[{group(v[3:], 8)}],[{','.join(str(int(c)) for c in cf)}],"
                   f"[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]]")
        if kind == "jointtarget":
            head.append(f"    CONST jointtarget j{k + 1}:=[[{group(deg, 4)}],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];")
            body.append(f"        MoveAbsJ j{k + 1}\\NoEOffs, vFast, z50, tGripper;")
        elif kind == "robtarget":
            head.append(f"    CONST robtarget p{k + 1}:={literal};")
            body.append(f"        Move{'L' if k % 2 else 'J'} p{k + 1}, v{500 if k % 2 else 1000}, z10, "
                        f"tGripper\\WObj:=wobjTable;")
        else:
            body.append(f"        MoveL {literal}, v200, fine, tGripper\\WObj:=wobjTable;")
        if k % 10 == 9:
            body.append("        WaitTime 0.5;")
    return "\n".join(head + body + ["    ENDPROC", "ENDMODULE", ""])


def tp_program(name: str, arm: Arm, q: np.ndarray, kinds: list[str], tool: tuple[int, np.ndarray],
               frame: tuple[int, np.ndarray]) -> str:
    """A FANUC TP program (.ls) visiting postures q (N, 6) rad, kinds[k] "joint" or "cartesian"; Cartesian
    positions in user frame frame[0] (robot base -> frame[1]) with tool tool[0] (faceplate -> tool[1])."""
    from gecgen.deliver.programs import fanuc

    config = fanuc.config(arm)
    main = ["/PROG  " + name.upper(), "/ATTR", "OWNER\t\t= MNEDITOR;", 'COMMENT\t\t= "cell cycle";',
            "PROTECT\t\t= READ_WRITE;", "DEFAULT_GROUP\t= 1,*,*,*,*;", "CONTROL_CODE\t= 00000000 00000000;", "/MN",
            f"   1:  UFRAME_NUM={frame[0]} ;", f"   2:  UTOOL_NUM={tool[0]} ;"]
    points = ["/POS"]
    for k, (qk, kind) in enumerate(zip(q, kinds)):
        main.append(f"{k + 3:4d}:{'J' if k % 3 == 0 else 'L'} P[{k + 1}] "
                    f"{'100%' if k % 3 == 0 else '500mm/sec'} {'FINE' if k % 5 == 4 else 'CNT50'}    ;")
        if kind == "joint":
            j = np.rad2deg(qk)
            body = (f"\tUF : {frame[0]}, UT : {tool[0]},\t\n"
                    f"\tJ1= {j[0]:9.3f} deg,\tJ2= {j[1]:9.3f} deg,\tJ3= {j[2]:9.3f} deg,\n"
                    f"\tJ4= {j[3]:9.3f} deg,\tJ5= {j[4]:9.3f} deg,\tJ6= {j[5]:9.3f} deg")
        else:
            P = np.linalg.inv(frame[1]) @ arm.fk(qk)[0] @ tool[1]
            v = pose_values(fanuc.FORMAT, P, ("mm",) * 3 + ("deg",) * 3)
            f, u, t, *turn = config(qk[None])[0]
            body = (f"\tUF : {frame[0]}, UT : {tool[0]},\t\tCONFIG : '{'F' if f else 'N'} {'U' if u else 'D'} "
                    f"{'T' if t else 'B'}, {turn[0]}, {turn[1]}, {turn[2]}',\n"
                    f"\tX = {v[0]:9.3f}  mm,\tY = {v[1]:9.3f}  mm,\tZ = {v[2]:9.3f}  mm,\n"
                    f"\tW = {v[3]:9.3f} deg,\tP = {v[4]:9.3f} deg,\tR = {v[5]:9.3f} deg")
        points.append(f"P[{k + 1}]{{\n   GP1:\n{body}\n}};")
    return "\n".join(main + points + ["/END", ""])
