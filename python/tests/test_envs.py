"""The package against gymnasium's checker, the Rust side's recorded trajectory and bad input."""

import json
import pathlib

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import muscle_rally as mr

ROOT = pathlib.Path(__file__).resolve().parents[2]
TRAJECTORY = ROOT / "agents" / "tests" / "fixtures" / "vecenv_trajectory.json"


def bits_sum(x: np.ndarray) -> int:
    """The wrapping sum of the float64 bit patterns, as agents/tests/vecenv.rs computes it."""
    return int(np.ascontiguousarray(x, dtype=np.float64).view(np.uint64).sum(dtype=np.uint64))


def test_gymnasiums_checker_passes_for_every_method():
    for method in mr.METHODS:
        env = mr.make("SingleServe-v0", method=method)
        check_env(env, skip_render_check=True)
        assert len(env.observation_names) == env.observation_space.shape[0]
        assert len(env.action_names) == env.action_space.shape[0]


def test_every_serve_distribution_plays():
    first = {}
    for serve in mr.SERVES:
        env = mr.make("SingleServe-v0", method="kmac", serve=serve)
        obs, _ = env.reset(seed=9)
        first[serve] = obs[env.observation_names.index("ball_vel.x")]
        env.step(np.zeros(13))
    # Four distributions, four different first balls from the same seed.
    assert len(set(first.values())) == len(mr.SERVES), first


def test_registered_with_gymnasium():
    env = gym.make("muscle_rally/SingleServe-v0", method="muscle-pd")
    obs, _ = env.reset(seed=1)
    assert obs.shape == env.observation_space.shape
    # gymnasium.make_vec builds the Rust vector env, not a Python loop over single ones.
    vec = gym.make_vec("muscle_rally/SingleServe-v0", num_envs=3, method="kmac",
                       vectorization_mode="vector_entry_point")
    assert isinstance(vec.unwrapped, mr.SingleServeVectorEnv) and vec.num_envs == 3
    obs, _ = vec.reset(seed=np.int64(4))
    assert obs.shape == (3, 206)


def test_the_same_seed_is_the_rust_sides_trajectory_bit_for_bit():
    rec = json.loads(TRAJECTORY.read_text())
    env = mr.make("SingleServe-v0", method=rec["method"], model=rec["model"])
    obs, info = env.reset(seed=rec["seed"])
    assert info["seed"] == rec["seed"]
    sums, rewards, ended = [bits_sum(obs)], [], None
    width = env.action_space.shape[0]
    for k in range(rec["steps"]):
        a = np.array([((k * 7 + j * 3) % 11) / 5.5 - 1.0 for j in range(width)])
        obs, r, term, trunc, _ = env.step(a)
        sums.append(bits_sum(obs))
        rewards.append(r)
        if ended is None and (term or trunc):
            ended = k
    assert sums == rec["obs_bits_sum"]
    assert [np.float64(r).tobytes() for r in rewards] == \
        [np.float64(r).tobytes() for r in rec["rewards"]]
    assert ended == rec["ended_at"]


def test_the_vector_env_steps_every_environment_as_a_single_one_would():
    vec = mr.make_vec("SingleServe-v0", num_envs=4, method="kmac")
    obs, info = vec.reset(seed=10)
    assert obs.shape == (4, 206) and list(info["seed"]) == [10, 11, 12, 13]
    single = mr.make("SingleServe-v0", method="kmac")
    one, _ = single.reset(seed=12)
    np.testing.assert_array_equal(obs[2], one)
    rng = np.random.default_rng(0)
    episodes_ended = 0
    for _ in range(60):
        a = rng.uniform(-1, 1, size=(4, 13))
        obs, r, term, trunc, infos = vec.step(a)
        # Each reward term's share, named as the configuration names the weights; they sum to it.
        parts = infos["reward_terms"]
        assert list(parts) == vec.reward_term_names and "grasp" in parts
        np.testing.assert_allclose(sum(parts.values()), r, rtol=1e-12, atol=1e-9)
        if episodes_ended == 0:
            o1, r1, t1, u1, i1 = single.step(a[2])
            np.testing.assert_array_equal(obs[2] if not (t1 or u1) else infos["final_obs"][2], o1)
            assert r[2] == r1
            assert i1["reward_terms"] == {n: parts[n][2] for n in parts}
        done = term | trunc
        if done.any():
            episodes_ended += int(done.sum())
            assert infos["_final_obs"].tolist() == done.tolist()
            # The ended episodes' last flags in final_info; the rows restarted begin afresh.
            assert infos["_final_info"].tolist() == done.tolist()
            assert not (infos["hit"][done].any() or infos["success"][done].any())
            assert not (infos["final_info"]["hit"] & ~done).any()
    assert obs.shape == (4, 206) and np.isfinite(obs).all()


def test_bad_arguments_raise_with_the_argument_named():
    with pytest.raises(ValueError, match="method"):
        mr.make("SingleServe-v0", method="ppo")
    with pytest.raises(ValueError, match="serve"):
        mr.make("SingleServe-v0", serve="lob")
    with pytest.raises(ValueError, match="num_envs"):
        mr.make_vec("SingleServe-v0", num_envs=0)
    with pytest.raises(ValueError, match="env_id"):
        mr.make("Tennis-v0")
    with pytest.raises(ValueError, match="model"):
        mr.make("SingleServe-v0", model="/nonexistent/robot.xml")
    with pytest.raises(ValueError, match="config"):
        mr.make("SingleServe-v0", config="/nonexistent/train.toml")
    env = mr.make("SingleServe-v0")
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(13))
    with pytest.raises(ValueError, match="seed"):
        env.reset(seed=-1)
    vec = mr.make_vec("SingleServe-v0", num_envs=np.int64(2))
    with pytest.raises(gym.error.ResetNeeded):
        vec.step(np.zeros((2, 13)))
    with pytest.raises(ValueError, match="seed"):
        vec.reset(seed=2**64 - 1)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(np.zeros(3))
    # A non-finite action ends the episode (the rules' invalid action), it does not raise.
    _, r, term, _, _ = env.step(np.full(13, np.nan))
    assert term and r == 0.0


def test_the_rally_passes_pettingzoos_parallel_api_test():
    from pettingzoo.test import parallel_api_test

    env = mr.rally.parallel_env(method="kmac")
    parallel_api_test(env, num_cycles=200)
    obs, infos = env.reset(seed=3)
    assert set(obs) == {"a", "b"} and obs["a"].shape == (206,)
    # Each robot observes in its own frame: the two observations differ.
    assert not np.array_equal(obs["a"], obs["b"])
    steps = 0
    while env.agents:
        obs, rewards, terms, truncs, infos = env.step({a: np.zeros(13) for a in env.agents})
        steps += 1
        for a in ("a", "b"):
            assert abs(sum(infos[a]["reward_terms"].values()) - rewards[a]) < 1e-9
    assert steps > 10 and (any(terms.values()) or any(truncs.values()))
    with pytest.raises(gym.error.ResetNeeded):
        env.step({a: np.zeros(13) for a in ("a", "b")})
    with pytest.raises(ValueError, match="actions"):
        env.reset(seed=3)
        env.step({"a": np.zeros(13)})


def mlp_onnx(weights, activation="Tanh") -> bytes:
    """An MLP as PyTorch exports one (Gemm with transposed weights, then the activation), built
    with the onnx package from numpy weights: [(W, b), ...], W of shape (out, in)."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    nodes, inits, x = [], [], "obs"
    for k, (w, b) in enumerate(weights):
        inits += [numpy_helper.from_array(w.astype(np.float32), f"w{k}"),
                  numpy_helper.from_array(b.astype(np.float32), f"b{k}")]
        y = f"h{k}" if k + 1 < len(weights) else "act"
        pre = f"z{k}" if k + 1 < len(weights) else y
        nodes.append(helper.make_node("Gemm", [x, f"w{k}", f"b{k}"], [pre], transB=1))
        if k + 1 < len(weights):
            nodes.append(helper.make_node(activation, [pre], [y]))
        x = y
    n_in, n_out = weights[0][0].shape[1], weights[-1][0].shape[0]
    graph = helper.make_graph(
        nodes, "policy",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", n_in])],
        [helper.make_tensor_value_info("act", TensorProto.FLOAT, ["batch", n_out])], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    onnx.checker.check_model(model)
    return model.SerializeToString()


def test_an_onnx_network_from_numpy_weights_becomes_a_checkpoint():
    pytest.importorskip("onnx")
    rng = np.random.default_rng(1)
    w = [(rng.normal(0, 0.1, (32, 206)), np.zeros(32)), (rng.normal(0, 0.1, (13, 32)), np.zeros(13))]
    mean, std = list(rng.normal(0, 1, 206)), list(rng.uniform(0.5, 2, 206))
    text = mr.checkpoint_from_onnx(mlp_onnx(w), method="kmac", name="mine", obs_mean=mean,
                                   obs_std=std)
    c = json.loads(text)
    assert c["name"] == "mine" and c["model"] == "default"
    assert c["controller"]["kind"] == "kmac" and "onnx" in c and "policy" not in c
    assert c["observation"]["mean"] == mean and c["observation"]["std"] == std
    # The network's width is the method's: Muscle-PPO's controller wants another.
    with pytest.raises(ValueError, match="onnx"):
        mr.checkpoint_from_onnx(mlp_onnx(w), method="muscle", name="x")
    with pytest.raises(ValueError, match="obs_mean"):
        mr.checkpoint_from_onnx(mlp_onnx(w), method="kmac", name="x", obs_mean=mean)
    with pytest.raises(ValueError, match="observation"):
        mr.checkpoint_from_onnx(mlp_onnx(w), method="kmac", name="x", obs_mean=[0.0],
                                obs_std=[1.0])
    with pytest.raises(ValueError, match="onnx"):
        mr.checkpoint_from_onnx(b"not a network", method="kmac", name="x")


def test_rally_eval_of_an_onnx_checkpoint_plays_the_numpy_forward_of_its_weights(tmp_path):
    pytest.importorskip("onnx")
    rng = np.random.default_rng(2)
    w = [(rng.normal(0, 0.2, (24, 206)), rng.normal(0, 0.1, 24)),
         (rng.normal(0, 0.3, (13, 24)), rng.normal(0, 0.1, 13))]
    mean, std = rng.normal(0, 1, 206), rng.uniform(0.5, 2, 206)
    path = tmp_path / "mine.json"
    path.write_text(mr.checkpoint_from_onnx(mlp_onnx(w), method="kmac", name="mine",
                                            obs_mean=list(mean), obs_std=list(std)))
    report = mr.evaluate(path, episodes=3, seed=11, mean_action=True, trace=True)
    assert report["episodes"] == 3 and report["seed"] == 11
    t = report["trace"]
    assert sorted(set(t["episode"].tolist())) == [0, 1, 2]
    assert t["observation"].shape == (len(t["step"]), 206) and t["action"].shape[1] == 13
    # The network's input is the normalised observation in float32, as an exported policy sees it.
    x = ((t["observation"] - mean) / std).astype(np.float32)
    h = np.tanh(x @ w[0][0].T.astype(np.float32) + w[0][1].astype(np.float32))
    a = h @ w[1][0].T.astype(np.float32) + w[1][1].astype(np.float32)
    np.testing.assert_allclose(t["action"], a, rtol=1e-5, atol=1e-5)
    assert np.abs(a).max() > 0.1, "the test's weights move the robot"
    # The same evaluation without the trace gives the same report; rally eval's bad arguments.
    again = mr.evaluate(str(path), episodes=3, seed=11, mean_action=True)
    assert again == {k: v for k, v in report.items() if k != "trace"}
    with pytest.raises(ValueError, match="trace"):
        mr.evaluate(path, episodes=101, trace=True)
    with pytest.raises(ValueError, match="agent"):
        mr.evaluate(tmp_path / "missing.json")
    with pytest.raises(ValueError, match="serve"):
        mr.evaluate("scripted", serve="lob")
    with pytest.raises(ValueError, match="episodes"):
        mr.evaluate("scripted", episodes=0)


def myochallenge_or_skip():
    """MyoSuite's robot once ``rally model import myosuite`` has run (CI imports it and sets
    RALLY_REQUIRE_MYOCHALLENGE, so there the test cannot skip)."""
    import os

    try:
        return mr.make("SingleServe-v0", method="kmac", model="myochallenge")
    except ValueError as e:
        if "rally model import" in str(e) and not os.environ.get("RALLY_REQUIRE_MYOCHALLENGE"):
            pytest.skip("MyoSuite's robot not imported (rally model import myosuite)")
        raise


def test_myosuites_robot_in_every_face():
    env = myochallenge_or_skip()
    assert env.model == "myochallenge"
    assert env.observation_space.shape == (640,) and env.action_space.shape == (32,)
    check_env(env, skip_render_check=True)
    muscle = mr.make("SingleServe-v0", method="muscle", model="myochallenge")
    assert muscle.action_space.shape == (275,)
    assert [n for n in env.action_names if "pelvis" in n] == ["target.pelvis_x", "target.pelvis_y"]
    vec = mr.make_vec("SingleServe-v0", num_envs=2, method="kmac", model="myochallenge")
    obs, _ = vec.reset(seed=4)
    one, _ = env.reset(seed=5)
    np.testing.assert_array_equal(obs[1], one)
    for _ in range(20):
        obs, r, term, trunc, infos = vec.step(np.zeros((2, 32)))
        np.testing.assert_allclose(sum(infos["reward_terms"].values()), r, atol=1e-9)
    report = mr.evaluate("kmac", model="myochallenge", episodes=4, seed=3)
    # The built-in "kmac" of this robot (the default robot's would not fit its 640 observations).
    assert report["episodes"] == 4 and report["agent"] == "kmac"
