"""How fast the Python package steps, next to the Rust environments alone, in one run.

    python python/benchmarks/speed.py                      # the built-in robot
    python python/benchmarks/speed.py --model myochallenge --myosuite PYTHON

Measures, each for ``--seconds``:
  - physics alone: ``rally bench train``'s ceiling, the worlds stepped on every core with every
    muscle at 0.1 (no controller, observation or reward);
  - Rust alone: the package's own environments (controller, observation, reward) stepped in a Rust
    loop with zero actions, N = 64;
  - Python: ``make_vec(num_envs=N)`` stepped from Python with zero actions for N = 1, 16, 64 (the
    gymnasium VectorEnv: arrays, infos, autoreset), and the bare ``_core.VecEnv`` at N = 64;
  - with ``--myosuite PYTHON`` (an interpreter with ``myosuite``, e.g. the one ``rally model import
    myosuite`` made): MyoSuite's own ``myoChallengeTableTennisP2-v0``, one environment, zero actions
    (its control step is ours: 5 steps of 2 ms).
Prints a table (``--json`` for one object). The Python layer's cost at N = 64 is 1 - Python / Rust
alone. Run it on an idle machine: another process on the cores changes every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

import muscle_rally as mr
from muscle_rally import _core

MYOSUITE = """
import sys, time, numpy as np
from myosuite.utils import gym
env = gym.make("myoChallengeTableTennisP2-v0")
env.reset(seed=0)
a = np.zeros(env.action_space.shape)
for _ in range(50):
    env.step(a)
steps, start, seconds = 0, time.perf_counter(), float(sys.argv[1])
while time.perf_counter() - start < seconds:
    _, _, term, trunc, _ = env.step(a)
    steps += 1
    if term or trunc:
        env.reset()
print(steps / (time.perf_counter() - start))
"""


def python_rate(model: str, method: str, n: int, seconds: float) -> float:
    """Env steps/s of ``make_vec(num_envs=n)`` stepped from Python."""
    env = mr.make_vec("SingleServe-v0", num_envs=n, method=method, model=model)
    env.reset(seed=0)
    a = np.zeros(env.action_space.shape)
    for _ in range(5):
        env.step(a)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        env.step(a)
        steps += n
    return steps / (time.perf_counter() - start)


def bare_rate(model: str, method: str, n: int, seconds: float) -> float:
    """Env steps/s of ``_core.VecEnv.step`` called from Python without the gymnasium wrapper (no
    infos, no copies; ended episodes started again as the wrapper does)."""
    core = _core.VecEnv(method, n, model)
    rows = core.num_envs
    obs = np.zeros((rows, core.obs_dim))
    flags = [np.zeros(rows, dtype=np.bool_) for _ in range(4)]
    rewards, acts = np.zeros(rows), np.zeros((rows, core.act_dim))
    steps, start, seed = 0, time.perf_counter(), n
    while time.perf_counter() - start < seconds:
        core.step(acts, obs, rewards, *flags)
        steps += n
        for i in np.flatnonzero(flags[0] | flags[1]):
            core.reset(int(i), seed, obs[i:i + 1])
            seed += 1
    return steps / (time.perf_counter() - start)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", default="default", help="default, myochallenge or an MJCF file")
    p.add_argument("--method", default="kmac", choices=mr.METHODS)
    p.add_argument("--seconds", type=float, default=5.0, help="seconds for each figure")
    p.add_argument("--myosuite", metavar="PYTHON",
                   help="also time MyoSuite's own environment with this interpreter")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    args = p.parse_args()
    s, m = args.seconds, args.model
    r: dict = {"model": m, "method": args.method, "seconds": s, "cores": os.cpu_count()}
    r["physics_alone"] = _core.physics_alone(m, 64, s)
    rust = _core.VecEnv(args.method, 64, m)
    start = time.perf_counter()
    steps = rust.run_fixed(np.zeros(rust.act_dim), s)
    r["rust_alone_64"] = steps / (time.perf_counter() - start)
    for n in (1, 16, 64):
        r[f"python_{n}"] = python_rate(m, args.method, n, s)
    r["python_bare_64"] = bare_rate(m, args.method, 64, s)
    r["python_cost_64"] = 1.0 - r["python_64"] / r["rust_alone_64"]
    if args.myosuite:
        out = subprocess.run([args.myosuite, "-c", MYOSUITE, str(s)], capture_output=True,
                             text=True)
        if out.returncode != 0:
            print(out.stderr, file=sys.stderr)
            print("--myosuite: MyoSuite's environment did not run (above)", file=sys.stderr)
            return 1
        r["myosuite_1"] = float(out.stdout.strip().splitlines()[-1])
    if args.json:
        print(json.dumps(r))
        return 0
    print(f"{m} robot, {args.method}, {r['cores']} cores, {s:g} s each (env steps/s)")
    print(f"  physics alone (rally bench train's ceiling, 64 worlds)  {r['physics_alone']:>9.0f}")
    print(f"  Rust alone (the package's environments, N = 64)         {r['rust_alone_64']:>9.0f}")
    for n in (1, 16, 64):
        print(f"  Python make_vec, N = {n:<2}                                {r[f'python_{n}']:>9.0f}")
    print(f"  Python _core.VecEnv bare, N = 64                        {r['python_bare_64']:>9.0f}")
    print(f"  the Python layer's cost at N = 64: {100 * r['python_cost_64']:.0f}%")
    if "myosuite_1" in r:
        print(f"  MyoSuite's myoChallengeTableTennisP2-v0, 1 env        {r['myosuite_1']:>9.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
