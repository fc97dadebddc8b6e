#!/usr/bin/env python3
"""Writes a small ONNX policy and numpy's outputs for it, the fixture of agents/tests/onnx.rs.

    python tools/make_onnx_policy.py [--obs 206] [--act 13] [--hidden 64] [--out agents/tests/fixtures]

The network is a PyTorch-style MLP (Gemm with transB=1, Tanh, Gemm) with a dynamic batch, random
weights from a seeded generator; `policy_expected.json` holds five random observations and the actions
numpy computes for them (float32, as ONNX runs). Needs `pip install onnx numpy`.

It also writes `policy_variable_width.onnx`, a hostile policy: `act` finite entries for the zero
observation (so it passes validation), two more for each negative observation entry (the player must
refuse its action, not index past it); and `policy_big_constant.onnx`, a few hundred bytes that
materialise a 10^9-byte constant (ConstantOfShape of 250 000 000 floats, summed into the action), which
the checkpoint reader must refuse before it allocates.
"""
import argparse
import json
import os

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--obs", type=int, default=206)
    ap.add_argument("--act", type=int, default=13)
    ap.add_argument("--hidden", type=int, default=64)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "..", "agents", "tests", "fixtures"))
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    w1 = (rng.standard_normal((args.hidden, args.obs)) * 0.1).astype(np.float32)
    b1 = (rng.standard_normal(args.hidden) * 0.1).astype(np.float32)
    w2 = (rng.standard_normal((args.act, args.hidden)) * 0.3).astype(np.float32)
    b2 = (rng.standard_normal(args.act) * 0.1).astype(np.float32)
    nodes = [
        helper.make_node("Gemm", ["obs", "w1", "b1"], ["h"], transB=1),
        helper.make_node("Tanh", ["h"], ["t"]),
        helper.make_node("Gemm", ["t", "w2", "b2"], ["action"], transB=1),
    ]
    graph = helper.make_graph(
        nodes,
        "policy",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", args.obs])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", args.act])],
        [numpy_helper.from_array(w1, "w1"), numpy_helper.from_array(b1, "b1"),
         numpy_helper.from_array(w2, "w2"), numpy_helper.from_array(b2, "b2")],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    os.makedirs(args.out, exist_ok=True)
    onnx.save(model, os.path.join(args.out, "policy.onnx"))
    # Hostile: its width is 11 + 2 (k + 1), k the negative observation entries (NonZero gives the row
    # and column of each of them and of one constant entry, so it is never empty): 13 at zero. The
    # entries are zeros and those indices, all finite.
    wide = helper.make_graph(
        [
            helper.make_node("Mul", ["obs", "zero"], ["z"]),
            helper.make_node("Slice", ["z", "start", "end", "axis"], ["base"]),
            helper.make_node("Less", ["obs", "zero"], ["negative"]),
            helper.make_node("Cast", ["negative"], ["negative_f"], to=TensorProto.FLOAT),
            helper.make_node("Concat", ["negative_f", "one"], ["mask"], axis=1),
            helper.make_node("NonZero", ["mask"], ["where"]),
            helper.make_node("Cast", ["where"], ["where_f"], to=TensorProto.FLOAT),
            helper.make_node("Flatten", ["where_f"], ["extra"], axis=0),
            helper.make_node("Concat", ["base", "extra"], ["action"], axis=1),
        ],
        "variable_width",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, args.obs])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, [1, None])],
        [numpy_helper.from_array(np.zeros(1, np.float32), "zero"),
         numpy_helper.from_array(np.ones((1, 1), np.float32), "one"),
         numpy_helper.from_array(np.array([0], np.int64), "start"),
         numpy_helper.from_array(np.array([args.act - 2], np.int64), "end"),
         numpy_helper.from_array(np.array([1], np.int64), "axis")],
    )
    hostile = helper.make_model(wide, opset_imports=[helper.make_opsetid("", 13)])
    hostile.ir_version = 8
    onnx.checker.check_model(hostile)
    onnx.save(hostile, os.path.join(args.out, "policy_variable_width.onnx"))
    big_constant(args)
    computed_big(args)
    slow(args)
    x = rng.standard_normal((5, args.obs)).astype(np.float32)
    y = np.tanh(x @ w1.T + b1) @ w2.T + b2
    with open(os.path.join(args.out, "policy_expected.json"), "w") as f:
        json.dump({"inputs": x.tolist(), "outputs": y.astype(np.float32).tolist()}, f)
    print(f"wrote policy.onnx ({args.obs} -> {args.hidden} -> {args.act}), policy_expected.json and "
          f"policy_variable_width.onnx to {args.out}")


def big_constant(args):
    graph = helper.make_graph(
        [
            helper.make_node("Slice", ["obs", "start", "end", "axis"], ["head"]),
            helper.make_node("ConstantOfShape", ["size"], ["big"],
                             value=numpy_helper.from_array(np.ones(1, np.float32))),
            helper.make_node("ReduceSum", ["big"], ["total"], keepdims=1),
            helper.make_node("Mul", ["total", "zero"], ["nothing"]),
            helper.make_node("Add", ["head", "nothing"], ["action"]),
        ],
        "big_constant",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, args.obs])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, [1, args.act])],
        [numpy_helper.from_array(np.array([250_000_000], np.int64), "size"),
         numpy_helper.from_array(np.zeros(1, np.float32), "zero"),
         numpy_helper.from_array(np.array([0], np.int64), "start"),
         numpy_helper.from_array(np.array([args.act], np.int64), "end"),
         numpy_helper.from_array(np.array([1], np.int64), "axis")],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, os.path.join(args.out, "policy_big_constant.onnx"))


def save(graph, args, name):
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, os.path.join(args.out, name))


def computed_big(args):
    # Shape(obs) = [1, obs], times [1, 1e9 / obs]: [1, ~1e9] floats, ~4 GB, known only once the
    # shape is computed.
    per = 1_000_000_000 // args.obs
    graph = helper.make_graph(
        [
            helper.make_node("Slice", ["obs", "start", "end", "axis"], ["head"]),
            helper.make_node("Shape", ["obs"], ["shape"]),
            helper.make_node("Mul", ["shape", "factor"], ["size"]),
            helper.make_node("ConstantOfShape", ["size"], ["big"],
                             value=numpy_helper.from_array(np.ones(1, np.float32))),
            helper.make_node("ReduceSum", ["big"], ["total"], keepdims=1),
            helper.make_node("Mul", ["total", "zero"], ["nothing"]),
            helper.make_node("Add", ["head", "nothing"], ["action"]),
        ],
        "computed_big",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, args.obs])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, [1, args.act])],
        [numpy_helper.from_array(np.array([1, per], np.int64), "factor"),
         numpy_helper.from_array(np.zeros(1, np.float32), "zero"),
         numpy_helper.from_array(np.array([0], np.int64), "start"),
         numpy_helper.from_array(np.array([args.act], np.int64), "end"),
         numpy_helper.from_array(np.array([1], np.int64), "axis")],
    )
    save(graph, args, "policy_computed_big.onnx")


def slow(args):
    # x (the first 64 observation entries) times a constant 64 x 64 matrix of 1/64, 2 000 times.
    depth = 2000
    nodes = [
        helper.make_node("Slice", ["obs", "start", "width", "axis"], ["x0"]),
        helper.make_node("ConstantOfShape", ["square"], ["w"],
                         value=numpy_helper.from_array(np.full(1, 1 / 64, np.float32))),
    ]
    for i in range(depth):
        nodes.append(helper.make_node("MatMul", [f"x{i}", "w"], [f"x{i + 1}"]))
    nodes.append(helper.make_node("Slice", [f"x{depth}", "start", "end", "axis"], ["action"]))
    graph = helper.make_graph(
        nodes,
        "slow",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, args.obs])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, [1, args.act])],
        [numpy_helper.from_array(np.array([64, 64], np.int64), "square"),
         numpy_helper.from_array(np.array([0], np.int64), "start"),
         numpy_helper.from_array(np.array([64], np.int64), "width"),
         numpy_helper.from_array(np.array([args.act], np.int64), "end"),
         numpy_helper.from_array(np.array([1], np.int64), "axis")],
    )
    save(graph, args, "policy_slow.onnx")


if __name__ == "__main__":
    main()
