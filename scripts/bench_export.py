"""Size and speed of the exported controller (docs/howto/export.md#size-and-speed).

    python scripts/bench_export.py                                   # the paper map, 1 -> 3 -> 4 -> 5 -> 6
    python scripts/bench_export.py --map rooms --ts-dir /tmp/rooms   # the ~1,000-cell rooms map, 1 -> 2

Builds (or loads, ``--ts-dir``) the abstraction (HiGHS, r = 0.2, L_max = 10), plans, exports C and
Python, compiles the C (``cc -O2``) and prints: the bytes of the controller's data per transition of
the plan (the npz arrays, and the compiled object's text + data), the time of one C step (``runs``
controllers stepped at once through ``tubejax_controller_step_many``, so ctypes' call cost is shared)
and of one Python step (one run, step by step). Disturbances are adversarial; every status is
checked to be in the tube. CPU times (``time.process_time``, best of several repeats): the machine may be shared.
"""

from __future__ import annotations

import argparse
import ctypes
import importlib.util
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import tubejax as tj  # noqa: E402
from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.analyses.control import plan_controller, plan_sequence, sample_polytope  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace import load_grid_map, parse_grid_map  # noqa: E402
from tubejax.model.workspace.generate import rooms_and_corridors_map  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


class CState(ctypes.Structure):
    _fields_ = [("pos", ctypes.c_int), ("l", ctypes.c_int), ("finished", ctypes.c_int), ("last", ctypes.c_int),
                ("rounds", ctypes.c_longlong)]


def system_and_plan(name: str, ts_dir):
    d = (load_grid_map(ROOT / "conf" / "workspace" / "maps" / "paper.txt") if name == "paper"
         else parse_grid_map(rooms_and_corridors_map(1000, seed=0), name="rooms"))
    if ts_dir and (Path(ts_dir) / "transitions.json").is_file():
        ts = tj.load(ts_dir)
    else:
        s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
        ts = build_abstraction(d, s, L_max=10, progress=False)
        if ts_dir:
            ts.save(ts_dir)
    seq = ["3", "4", "5", "6"] if name == "paper" else ["2"]
    return ts, plan_sequence(ts, ts.decomposition.cells_with_label("1")[0], seq)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--map", choices=["paper", "rooms"], default="paper")
    ap.add_argument("--ts-dir", default=None, help="load (or save) the abstraction here")
    ap.add_argument("--runs", type=int, default=2000)
    ap.add_argument("--weights", choices=["triangulation", "multilinear"], default="triangulation")
    args = ap.parse_args(argv)
    cc = shutil.which("cc") or shutil.which("gcc")
    ts, plan = system_and_plan(args.map, args.ts_dir)
    n_tr = len(plan.edges)
    print(f"{args.map} ({args.weights} weights): {ts.n_cells} cells, {ts.n_edges} edges; plan {n_tr} transitions "
          f"({len(set(plan.edges))} distinct), {plan.cost} steps")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        tj.export_controller(ts, plan, out, weights=args.weights)
        with np.load(out / "tubejax_controller.npz") as z:
            data_bytes = sum(z[k].nbytes for k in z.files)
        subprocess.run([cc, "-std=c99", "-O2", "-c", str(out / "tubejax_controller.c"), "-o",
                        str(out / "tc.o")], check=True)
        text, data = (int(v) for v in subprocess.run(["size", str(out / "tc.o")], capture_output=True, text=True,
                                                     check=True).stdout.splitlines()[1].split()[:2])
        print(f"data (npz arrays): {data_bytes} B = {data_bytes / n_tr:.0f} B per transition; "
              f"C object text+data: {text + data} B = {(text + data) / n_tr:.0f} B per transition")
        subprocess.run([cc, "-std=c99", "-O2", "-shared", "-fPIC", str(out / "tubejax_controller.c"), "-o",
                        str(out / "tc.so"), "-lm"], check=True)
        lib = ctypes.CDLL(str(out / "tc.so"))
        dp = ctypes.POINTER(ctypes.c_double)
        R, S = args.runs, plan.cost
        states = (CState * R)()
        for s in states:
            lib.tubejax_controller_init(ctypes.byref(s))
        ctrl = plan_controller(ts, plan, jnp.float64)
        H, h = np.asarray(ctrl.H), np.asarray(ctrl.h)
        X = np.asarray(sample_polytope(jax.random.PRNGKey(0), ts.decomposition.cells[plan.cells[0]], R))
        traj = [X.copy()]
        U = np.zeros((R, ts.system.m))
        status = np.zeros(R, np.int32)
        ip = ctypes.POINTER(ctypes.c_int)
        for t in range(S):                       # the closed loop, recording every state
            lib.tubejax_controller_step_many(states, R, traj[t].ctypes.data_as(dp), U.ctypes.data_as(dp),
                                             status.ctypes.data_as(ip))
            assert np.all(status >= 0), f"step {t}: a state outside its tube"
            xbar = traj[t] @ ts.system.A.T + U @ ts.system.B.T
            a = H[t + 1][np.argmin(h[t + 1][None] - xbar @ H[t + 1].T, axis=1)]
            traj.append(np.ascontiguousarray(xbar + ts.system.W.radius * a / np.linalg.norm(a, axis=1,
                                                                                              keepdims=True)))
        c_time = np.inf
        for _ in range(5):                       # the same states again, timed: best of 5
            for s in states:
                lib.tubejax_controller_init(ctypes.byref(s))
            t0 = time.process_time()
            for t in range(S):
                lib.tubejax_controller_step_many(states, R, traj[t].ctypes.data_as(dp), U.ctypes.data_as(dp),
                                                 status.ctypes.data_as(ip))
            c_time = min(c_time, time.process_time() - t0)
        traj = [x[0] for x in traj]
        spec = importlib.util.spec_from_file_location("tc_bench", out / "tubejax_controller.py")
        tc = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(tc)
        ctl = tc.Controller(out)
        best = np.inf
        for _ in range(3):
            st, u = ctl.init(), np.zeros(ts.system.m)
            t0 = time.process_time()
            for t in range(S):
                ctl.step(st, traj[t], u)
            best = min(best, (time.process_time() - t0) / S)
        print(f"one step: C {1e9 * c_time / (R * S):.0f} ns (best of 5: {R} runs x {S} steps through step_many); "
              f"Python (NumPy) {1e6 * best:.1f} us (best of 3 runs of {S} steps)")


if __name__ == "__main__":
    main()
