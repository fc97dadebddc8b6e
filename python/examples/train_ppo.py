"""Train a policy with your own PyTorch PPO on muscle_rally's vector environment, export it as
ONNX, turn it into a checkpoint, evaluate it as `rally eval` does, and (optionally) submit it to a
tournament server and play a match against a built-in agent.

    pip install ./python torch onnx
    python python/examples/train_ppo.py --method kmac --steps 2e6 --out runs/py-kmac
    python python/examples/train_ppo.py --out runs/py-kmac --resume --steps 4e6   # continue
    python python/examples/train_ppo.py --out runs/py-kmac --resume --steps 0 \\
        --server http://127.0.0.1:8080 --token "$T" --name py-kmac --opponent scripted

A single-file PPO in the style of CleanRL's (clipped surrogate, GAE, a state-independent Gaussian,
observations normalised by running statistics, the learning rate annealed to zero): a starting point
to replace with your own stack, not a tuned recipe — `rally train` is the tuned one (its settings in
config/train.toml). On the built-in robot `rally train`'s K-MAC first hits 30% of serves after about
0.9 M steps; the server admits an agent from 30% (`qualification_min_hit_rate`), so a shorter run is
refused with its figures.
"""

from __future__ import annotations

import argparse
import io
import json
import pathlib
import sys
import time
import urllib.error
import urllib.request
import warnings

import numpy as np
import torch
from torch import nn

import muscle_rally as mr


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--method", default="kmac", choices=mr.METHODS)
    p.add_argument("--model", default="default", help="default, myochallenge or an MJCF file")
    p.add_argument("--steps", type=float, default=2e6, help="env steps to train in all (default 2e6)")
    p.add_argument("--num-envs", type=int, default=32)
    p.add_argument("--rollout", type=int, default=64, help="steps per environment per iteration")
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default="runs/python-ppo", help="directory for the state and outputs")
    p.add_argument("--resume", action="store_true", help="continue from OUT/state.pt")
    p.add_argument("--eval-episodes", type=int, default=200)
    p.add_argument("--eval-seed", type=int, default=2026, help="a seed training never saw")
    p.add_argument("--server", help="a tournament server, e.g. http://127.0.0.1:8080")
    p.add_argument("--token", help="a submitter or admin token of that server")
    p.add_argument("--name", default="python-ppo", help="the agent's name on the server")
    p.add_argument("--opponent", default="scripted", help="a built-in agent to play")
    return p.parse_args()


class RunningStats:
    """Running mean and variance of the observations (Chan et al.'s parallel update). The policy
    sees ``(x - mean) / std`` with ``std = sqrt(var) + 0.01`` and no clip: exactly what the
    checkpoint's normalisation does in evaluation and on the server."""

    def __init__(self, width: int):
        self.mean, self.var, self.count = np.zeros(width), np.ones(width), 1e-4

    def update(self, x: np.ndarray) -> None:
        m, v, n = x.mean(0), x.var(0), x.shape[0]
        total = self.count + n
        delta = m - self.mean
        self.mean = self.mean + delta * n / total
        self.var = (self.var * self.count + v * n + delta**2 * self.count * n / total) / total
        self.count = total

    def std(self) -> np.ndarray:
        return np.sqrt(self.var) + 0.01

    def normalise(self, x: np.ndarray) -> np.ndarray:
        return (x - self.mean) / self.std()


def mlp(n_in: int, n_out: int, out_gain: float) -> nn.Sequential:
    layers = [nn.Linear(n_in, 256), nn.Tanh(), nn.Linear(256, 256), nn.Tanh(),
              nn.Linear(256, n_out)]
    for layer in layers:
        if isinstance(layer, nn.Linear):
            nn.init.orthogonal_(layer.weight, np.sqrt(2) if layer is not layers[-1] else out_gain)
            nn.init.zeros_(layer.bias)
    return nn.Sequential(*layers)


class Agent(nn.Module):
    def __init__(self, obs_dim: int, act_dim: int):
        super().__init__()
        self.actor = mlp(obs_dim, act_dim, 0.01)
        self.critic = mlp(obs_dim, 1, 1.0)
        self.log_std = nn.Parameter(torch.full((act_dim,), -0.5))

    def dist(self, obs: torch.Tensor) -> torch.distributions.Normal:
        return torch.distributions.Normal(self.actor(obs), self.log_std.exp())


def train(args, envs, agent, stats, opt, state) -> None:
    n, T, gamma, lam = args.num_envs, args.rollout, 0.99, 0.95
    obs_dim, act_dim = envs.single_observation_space.shape[0], envs.single_action_space.shape[0]
    total = int(args.steps)
    obs, _ = envs.reset(seed=args.seed * 100_000 + state["iteration"] * n)
    buf_obs = torch.zeros((T, n, obs_dim))
    buf_act, buf_logp = torch.zeros((T, n, act_dim)), torch.zeros((T, n))
    buf_rew, buf_done, buf_val = torch.zeros((T, n)), torch.zeros((T, n)), torch.zeros((T, n))
    hits, wins, episodes, start = 0, 0, 0, time.time()
    while state["steps"] < total:
        for g in opt.param_groups:
            g["lr"] = args.lr * max(0.0, 1.0 - state["steps"] / total)
        for t in range(T):
            stats.update(obs)
            x = torch.as_tensor(stats.normalise(obs), dtype=torch.float32)
            with torch.no_grad():
                d = agent.dist(x)
                a = d.sample()
                buf_val[t] = agent.critic(x).squeeze(-1)
            buf_obs[t], buf_act[t], buf_logp[t] = x, a, d.log_prob(a).sum(-1)
            obs, r, term, trunc, info = envs.step(a.numpy().clip(-1, 1))
            r = 0.01 * r  # rewards run to ~1000 an episode
            done = term | trunc
            if trunc.any():  # bootstrap a time limit from the episode's last observation
                last = torch.as_tensor(stats.normalise(info["final_obs"]), dtype=torch.float32)
                with torch.no_grad():
                    r = r + gamma * trunc * agent.critic(last).squeeze(-1).numpy()
            buf_rew[t], buf_done[t] = torch.as_tensor(r), torch.as_tensor(done, dtype=torch.float32)
            if done.any():  # the ended episodes' last flags (the rows have started again)
                hits += int(info["final_info"]["hit"].sum())
                wins += int(info["final_info"]["success"].sum())
                episodes += int(done.sum())
        with torch.no_grad():
            x = torch.as_tensor(stats.normalise(obs), dtype=torch.float32)
            next_val = agent.critic(x).squeeze(-1)
        adv, last = torch.zeros((T, n)), torch.zeros(n)
        for t in reversed(range(T)):
            v_next = next_val if t == T - 1 else buf_val[t + 1]
            keep = 1.0 - buf_done[t]
            delta = buf_rew[t] + gamma * v_next * keep - buf_val[t]
            last = delta + gamma * lam * keep * last
            adv[t] = last
        ret = adv + buf_val
        b_obs, b_act = buf_obs.reshape(-1, obs_dim), buf_act.reshape(-1, act_dim)
        b_logp, b_adv, b_ret = buf_logp.reshape(-1), adv.reshape(-1), ret.reshape(-1)
        for _ in range(5):
            for mb in torch.randperm(T * n).chunk(4):
                d = agent.dist(b_obs[mb])
                ratio = (d.log_prob(b_act[mb]).sum(-1) - b_logp[mb]).exp()
                a_mb = (b_adv[mb] - b_adv[mb].mean()) / (b_adv[mb].std() + 1e-8)
                pg = -torch.min(ratio * a_mb, ratio.clamp(0.8, 1.2) * a_mb).mean()
                v = agent.critic(b_obs[mb]).squeeze(-1)
                loss = pg + 0.5 * ((v - b_ret[mb]) ** 2).mean()
                opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), 0.5)
                opt.step()
        state["steps"] += T * n
        state["iteration"] += 1
        if state["iteration"] % 10 == 0:
            rate = hits / max(episodes, 1), wins / max(episodes, 1)
            speed = T * n * 10 / (time.time() - start)
            print(f"{state['steps']:>9} steps  {speed:6.0f} steps/s  episodes {episodes:4}  "
                  f"hit {100 * rate[0]:5.1f}%  success {100 * rate[1]:5.1f}%", flush=True)
            state["curve"].append((state["steps"], rate[0], rate[1]))
            hits, wins, episodes, start = 0, 0, 0, time.time()
            save(args, agent, stats, opt, state)


def save(args, agent, stats, opt, state) -> None:
    out = pathlib.Path(args.out)
    torch.save({"agent": agent.state_dict(), "opt": opt.state_dict(), "state": state,
                "stats": (stats.mean, stats.var, stats.count)}, out / "state.pt.partial")
    (out / "state.pt.partial").replace(out / "state.pt")


def export(agent: Agent, stats: RunningStats, obs_dim: int, args) -> str:
    """The actor's mean as ONNX, wrapped with the observation statistics into a checkpoint."""
    buf = io.BytesIO()
    with warnings.catch_warnings():  # the TorchScript exporter: the newer one needs onnxscript
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(agent.actor, (torch.zeros(1, obs_dim),), buf, input_names=["obs"],
                          output_names=["action"], dynamic_axes={"obs": {0: "batch"}},
                          dynamo=False)
    return mr.checkpoint_from_onnx(buf.getvalue(), method=args.method, name=args.name,
                                   model=args.model, obs_mean=list(stats.mean),
                                   obs_std=list(stats.std()))


def call(server: str, path: str, token: str | None = None, body: dict | None = None) -> dict:
    req = urllib.request.Request(server.rstrip("/") + "/api/v1" + path,
                                 data=None if body is None else json.dumps(body).encode())
    req.add_header("Content-Type", "application/json")
    if token:
        req.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(req, timeout=600) as r:
            return json.loads(r.read())
    except urllib.error.HTTPError as e:
        raise SystemExit(f"{path}: HTTP {e.code}: {e.read().decode()}") from None


def main() -> int:
    args = parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)  # the environments take the cores
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    envs = mr.make_vec("SingleServe-v0", num_envs=args.num_envs, method=args.method,
                       model=args.model)
    obs_dim, act_dim = envs.single_observation_space.shape[0], envs.single_action_space.shape[0]
    agent, stats = Agent(obs_dim, act_dim), RunningStats(obs_dim)
    opt = torch.optim.Adam(agent.parameters(), lr=args.lr, eps=1e-5)
    state = {"steps": 0, "iteration": 0, "curve": []}
    if not args.resume and (out / "state.pt").exists():
        print(f"{out} holds a run: --resume to continue it (or another --out)", file=sys.stderr)
        return 2
    if args.resume:
        if not (out / "state.pt").exists():
            print(f"--resume: no run in {out} (no state.pt)", file=sys.stderr)
            return 2
        saved = torch.load(out / "state.pt", weights_only=False)
        agent.load_state_dict(saved["agent"])
        opt.load_state_dict(saved["opt"])
        state = saved["state"]
        stats.mean, stats.var, stats.count = saved["stats"]
        print(f"resumed at {state['steps']} steps")
    print(f"{args.method} on the {args.model} robot: {obs_dim} observations, {act_dim} actions, "
          f"{args.num_envs} environments")
    train(args, envs, agent, stats, opt, state)
    save(args, agent, stats, opt, state)

    text = export(agent, stats, obs_dim, args)
    path = out / "checkpoint.json"
    path.write_text(text)
    report = mr.evaluate(path, episodes=args.eval_episodes, seed=args.eval_seed,
                         model=args.model)
    hit, win = report["hit_rate"], report["success_rate"]
    print(f"{path}: hit {100 * hit['value']:.1f}% [{100 * hit['low']:.1f}, {100 * hit['high']:.1f}], "
          f"success {100 * win['value']:.1f}% on {report['episodes']} P2 serves of seed "
          f"{report['seed']} (rally eval {path} --model {args.model} --episodes "
          f"{report['episodes']} --seed {report['seed']} says the same)")

    if args.server:
        reply = call(args.server, "/agents", args.token,
                     {"name": args.name, "checkpoint": json.loads(text)})
        q = reply["qualification"]
        print(f"admitted as {reply['agent']['name']} (id {reply['agent']['id']}): hit "
              f"{100 * q['hit_rate']['value']:.0f}% of the qualification serves")
        match = call(args.server, "/matches", args.token,
                     {"a": args.name, "b": args.opponent, "rallies": 10, "seed": args.seed})
        while (m := call(args.server, f"/matches/{match['id']}"))["status"] not in (
                "done", "failed", "cancelled"):
            time.sleep(1)
        print(f"match {m['id']} against {args.opponent}: {m['status']}, points "
              f"{m.get('points_a')}-{m.get('points_b')}, mean rally length "
              f"{m.get('mean_rally_length')}  ({args.server}/replay?match={m['id']}&rally=0)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
