"""ONNX Runtime on the shapes of `frmd bench --synthetic` (scripts/peers.sh runs both in one go).

For each backbone, builds the student's network as an ONNX graph with random weights (latency
does not depend on them): input 40 (the reach task: 2 x 6 observations, 2 + 2 previous action
and rate, 12 x 2 noisy trajectory), the hidden layers with Mish (x tanh(softplus x)), output 42
(2 DoF x 21 ProDMP parameters). Times `session.run` from Python (one thread, batch 1) for the
fp32 graph and its int8 dynamic quantization (`quantize_dynamic`, int8 weights), and an Identity
graph (the Python call overhead alone). Prints one JSON object per line:
{"backbone", "runtime", "median_us", "p99_us", "calls"}.

Usage: python3 scripts/peers.py [--calls N] [--warmup N] BACKBONE... (mlp, mlp-paper)
"""

import argparse
import json
import os
import tempfile
import time

import numpy as np
import onnx
import onnxruntime as ort
from onnx import TensorProto, helper, numpy_helper
from onnxruntime.quantization import QuantType, quantize_dynamic

INPUT = 40
OUTPUT = 42
HIDDEN = {"mlp": [256, 256, 256], "mlp-paper": [512, 512, 256, 256]}


def mlp_graph(hidden, seed=7):
    rng = np.random.default_rng(seed)
    nodes, inits = [], []
    x, width = "x", INPUT
    for i, out in enumerate(hidden + [OUTPUT]):
        w = (rng.standard_normal((width, out)) / np.sqrt(width)).astype(np.float32)
        b = (0.01 * rng.standard_normal(out)).astype(np.float32)
        inits += [numpy_helper.from_array(w, f"w{i}"), numpy_helper.from_array(b, f"b{i}")]
        nodes.append(helper.make_node("MatMul", [x, f"w{i}"], [f"m{i}"]))
        nodes.append(helper.make_node("Add", [f"m{i}", f"b{i}"], [f"a{i}"]))
        x = f"a{i}"
        if i < len(hidden):
            nodes.append(helper.make_node("Softplus", [x], [f"sp{i}"]))
            nodes.append(helper.make_node("Tanh", [f"sp{i}"], [f"th{i}"]))
            nodes.append(helper.make_node("Mul", [x, f"th{i}"], [f"h{i}"]))
            x = f"h{i}"
        width = out
    nodes.append(helper.make_node("Identity", [x], ["y"]))
    graph = helper.make_graph(
        nodes,
        "student",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, INPUT])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, OUTPUT])],
        inits,
    )
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])


def identity_graph():
    graph = helper.make_graph(
        [helper.make_node("Identity", ["x"], ["y"])],
        "identity",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, INPUT])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, INPUT])],
    )
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])


def session(path):
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(path, options, providers=["CPUExecutionProvider"])


def time_session(sess, calls, warmup):
    x = np.full((1, INPUT), 0.1, dtype=np.float32)
    for _ in range(warmup):
        sess.run(None, {"x": x})
    times = np.empty(calls)
    for i in range(calls):
        start = time.perf_counter_ns()
        sess.run(None, {"x": x})
        times[i] = (time.perf_counter_ns() - start) / 1e3
    return float(np.median(times)), float(np.quantile(times, 0.99))


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("backbones", nargs="+", choices=sorted(HIDDEN))
    parser.add_argument("--calls", type=int, default=2000)
    parser.add_argument("--warmup", type=int, default=200)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        identity = os.path.join(tmp, "identity.onnx")
        onnx.save(identity_graph(), identity)
        for backbone in args.backbones:
            fp32 = os.path.join(tmp, f"{backbone}.onnx")
            int8 = os.path.join(tmp, f"{backbone}.int8.onnx")
            onnx.save(mlp_graph(HIDDEN[backbone]), fp32)
            quantize_dynamic(fp32, int8, weight_type=QuantType.QInt8)
            for runtime, path in [
                ("ort int8 dynamic", int8),
                ("ort fp32", fp32),
                ("ort identity (call overhead)", identity),
            ]:
                median, p99 = time_session(session(path), args.calls, args.warmup)
                row = {
                    "backbone": backbone,
                    "runtime": f"{runtime} {ort.__version__}",
                    "median_us": round(median, 2),
                    "p99_us": round(p99, 2),
                    "calls": args.calls,
                }
                print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
