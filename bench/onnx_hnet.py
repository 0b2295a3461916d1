"""H-Net from one of our weights files (`.bpk`) as an ONNX model, for timing ONNX Runtime against
the page and `hnet` on the very same network and weights (docs/benchmarks.md, issue #41).

The graph is what `HNet::predict_async` computes for one stereo pair (crates/hnet-model): inputs
`view_a` and `view_b` ([1, 3, H, W], RGB in [0, 1]); both views through the shared
encoder-decoder as one batch of two (with the two position planes when the weights use them);
outputs `mask_a` and `mask_b` ([1, 1, H, W], after the sigmoid) and `force` ([1, 3], newtons,
after the weights' force scale). Weights not shared between the views are not supported.

With --check DATASET, also runs the model in ONNX Runtime (Python) on the dataset's first pairs
and prints their forces next to `hnet eval --predictions`'s, so that the export can be checked
against our own network (bench/README.md). With --time RUNS, times ONNX Runtime's inference per
pair on `--threads` threads as `hnet bench model --weights` times ours: from two RGB byte images
to the masks and force in host memory, after one warm-up run.

Needs numpy, onnx and cbor2 (and onnxruntime and pillow for --check); no PyTorch.

Usage: python bench/onnx_hnet.py assets/hnet-cpu.bpk end2end/ort-bench/model/hnet-224.onnx
"""

import argparse
import json
import struct

import cbor2
import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

# The operators (Conv, ConvTranspose, MaxPool, ReduceMean, Gemm, ...) are all in opset 18, which
# ONNX Runtime Web 1.30 runs (end2end/ort-bench).
OPSET = 18
# burn-pack: magic (4 bytes), version (2), metadata length (4), CBOR metadata, then the tensors'
# bytes from the next 256-byte boundary (burn-pack's base.rs).
HEADER = 10
IR_VERSION = 10
ALIGNMENT = 256


def read_bpk(path):
    """The weights file's tensors (name -> float32 array) and its metadata."""
    data = open(path, "rb").read()
    if data[:4] != b"NRUB":
        raise SystemExit(f"{path}: not a burn-pack weights file")
    (length,) = struct.unpack("<I", data[6:10])
    meta = cbor2.loads(data[HEADER : HEADER + length])
    start = -(-(HEADER + length) // ALIGNMENT) * ALIGNMENT
    tensors = {}
    for name, t in meta["tensors"].items():
        if t["dtype"] != "F32":
            raise SystemExit(f"{path}: tensor {name} is {t['dtype']}, not F32")
        lo, hi = t["data_offsets"]
        values = np.frombuffer(data[start + lo : start + hi], dtype="<f4")
        tensors[name] = values.reshape(t["shape"]).copy()
    return tensors, meta["metadata"]


def build(tensors, config):
    """The ONNX model of H-Net with `config` (the file's `hnet.config`) and its tensors."""
    if not config.get("share_weights", True):
        raise SystemExit("weights not shared between the views are not supported")
    side = config["image_size"]
    height, width = side["height"], side["width"]
    depth = config["depth"]
    nodes, inits = [], []

    def const(name, array, dtype=np.float32):
        inits.append(numpy_helper.from_array(np.asarray(array, dtype=dtype), name))
        return name

    def param(path):
        return const(path, tensors[path])

    def node(op, inputs, name, **attrs):
        nodes.append(helper.make_node(op, inputs, [name], name=name, **attrs))
        return name

    def conv(x, path, relu, out):
        y = node("Conv", [x, param(f"{path}.weight"), param(f"{path}.bias")], out + ".conv",
                 pads=[1, 1, 1, 1], kernel_shape=[3, 3])
        return node("Relu", [y], out) if relu else y

    def double(x, path, out):
        return conv(conv(x, f"{path}.first", True, out + ".a"), f"{path}.second", True, out)

    def mean(x, out):
        axes = const(out + ".axes", [2, 3], np.int64)
        return node("ReduceMean", [x, axes], out, keepdims=0)

    x = node("Concat", ["view_a", "view_b"], "views", axis=0)
    if config.get("position_channels"):
        across = lambda i, n: (2 * i + 1) / n - 1  # noqa: E731 (HNet's with_position_channels)
        cols = np.array([[across(c, width) for c in range(width)]] * height)
        rows = np.array([[across(r, height)] * width for r in range(height)])
        planes = np.stack([cols, rows])[None].repeat(2, axis=0)
        x = node("Concat", [x, const("position_planes", planes)], "with_position", axis=1)
    skips = []
    for i in range(depth):
        x = double(x, f"segmentation.encoder.{i}", f"enc{i}")
        skips.append(x)
        x = node("MaxPool", [x], f"pool{i}", kernel_shape=[2, 2], strides=[2, 2])
    x = double(x, "segmentation.bottleneck", "bottleneck")
    pooled = [mean(x, "gap0")]
    for i, skip in enumerate(reversed(skips)):
        path = f"segmentation.decoder.{i}"
        up = node("ConvTranspose", [x, param(f"{path}.up.weight"), param(f"{path}.up.bias")],
                  f"up{i}", strides=[2, 2], pads=[1, 1, 1, 1], output_padding=[1, 1],
                  kernel_shape=[3, 3])
        x = node("Concat", [up, skip], f"cat{i}", axis=1)
        x = double(x, f"{path}.conv", f"dec{i}")
        pooled.append(mean(x, f"gap{i + 1}"))
    logits = node("Conv", [x, param("segmentation.head.weight"), param("segmentation.head.bias")],
                  "logits", kernel_shape=[1, 1])
    probabilities = node("Sigmoid", [logits], "probabilities")
    nodes.append(helper.make_node("Split", [probabilities, const("mask_split", [1, 1], np.int64)],
                                  ["mask_a", "mask_b"], axis=0, name="masks"))
    features = node("Concat", pooled, "pooled", axis=1)
    nodes.append(helper.make_node("Split", [features, const("pooled_split", [1, 1], np.int64)],
                                  ["pooled_a", "pooled_b"], axis=0, name="per_view"))
    x = node("Concat", ["pooled_a", "pooled_b"], "features", axis=1)
    for layer, relu in [("hidden1", True), ("hidden2", True), ("output", False)]:
        x = node("Gemm", [x, param(f"force.{layer}.weight"), param(f"force.{layer}.bias")],
                 f"force_{layer}")
        if relu:
            x = node("Relu", [x], f"force_{layer}_relu")
    scale = config.get("force_scale")
    if scale:
        x = node("Mul", [x, const("force_std", [scale["std_n"]])], "force_scaled")
        x = node("Add", [x, const("force_mean", [scale["mean_n"]])], "force_n")
    nodes.append(helper.make_node("Identity", [x], ["force"], name="force"))
    image = lambda name, c: helper.make_tensor_value_info(  # noqa: E731
        name, TensorProto.FLOAT, [1, c, height, width])
    graph = helper.make_graph(
        nodes, "hnet", [image("view_a", 3), image("view_b", 3)],
        [image("mask_a", 1), image("mask_b", 1),
         helper.make_tensor_value_info("force", TensorProto.FLOAT, [1, 3])],
        inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="hnet-studio bench/onnx_hnet.py")
    # ONNX Runtime Web 1.30 reads IR versions up to 10 and onnx 1.23 writes 14 by default.
    model.ir_version = IR_VERSION
    onnx.checker.check_model(model)
    return model


def check(model_path, dataset, pairs):
    """Forces of ONNX Runtime (Python) on the dataset's first pairs, as `hnet eval` reads them."""
    import onnxruntime
    from PIL import Image

    session = onnxruntime.InferenceSession(model_path, providers=["CPUExecutionProvider"])
    manifest = open(f"{dataset}/manifest.csv").read().splitlines()
    header = manifest[0].split(",")
    for line in manifest[1 : 1 + pairs]:
        row = dict(zip(header, line.split(",")))
        views = []
        for view in "ab":
            rgb = Image.open(f"{dataset}/samples/{row['id']}_view_{view}.png").convert("RGB")
            views.append((np.asarray(rgb, dtype=np.float32) / 255).transpose(2, 0, 1)[None])
        mask_a, _, force = session.run(None, {"view_a": views[0], "view_b": views[1]})
        print(json.dumps({"id": row["id"], "force_n": [round(float(f), 5) for f in force[0]],
                          "catheter_pixels_a": int((mask_a >= 0.5).sum())}))


def time_inference(model_path, runs, threads):
    """Mean and median seconds per pair of ONNX Runtime (Python, CPU) over `runs` runs."""
    import time

    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.graph_optimization_level = onnxruntime.GraphOptimizationLevel.ORT_ENABLE_ALL
    session = onnxruntime.InferenceSession(model_path, options, providers=["CPUExecutionProvider"])
    _, _, height, width = session.get_inputs()[0].shape
    # A mid-grey pair, as `hnet bench model` reads.
    pixels = np.full((height, width, 3), 128, dtype=np.uint8)

    def tensor(image):
        return np.ascontiguousarray((image.astype(np.float32) / 255).transpose(2, 0, 1)[None])

    def run():
        return session.run(None, {"view_a": tensor(pixels), "view_b": tensor(pixels)})

    run()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    print(json.dumps({"runtime": f"onnxruntime {onnxruntime.__version__}", "threads": threads,
                      "size": width, "runs": runs,
                      "infer_pair_s": sum(times) / runs,
                      "infer_pair_median_s": float(np.median(times))}))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights", help="an H-Net weights file (.bpk)")
    parser.add_argument("onnx", help="where to write the ONNX model")
    parser.add_argument("--check", metavar="DATASET", help="run it on a dataset's first pairs")
    parser.add_argument("--pairs", type=int, default=3)
    parser.add_argument("--size", type=int,
                        help="write the network for square images of this side (pixels) instead "
                             "of the size the file records (the weights fit any size)")
    parser.add_argument("--time", metavar="RUNS", type=int,
                        help="time ONNX Runtime's inference per pair over RUNS runs")
    parser.add_argument("--threads", type=int, default=2, help="ONNX Runtime's threads for --time")
    args = parser.parse_args()
    tensors, meta = read_bpk(args.weights)
    if meta.get("hnet.architecture") != "hnet":
        raise SystemExit(f"{args.weights}: holds {meta.get('hnet.architecture')}, not H-Net")
    config = json.loads(meta["hnet.config"])
    if args.size:
        config["image_size"] = {"width": args.size, "height": args.size}
    model = build(tensors, config)
    onnx.save(model, args.onnx)
    params = sum(t.size for t in tensors.values())
    side = config["image_size"]
    print(f"wrote {args.onnx}: H-Net from {args.weights} ({params} parameters), one "
          f"{side['width']}x{side['height']} pair, opset {OPSET}")
    if args.check:
        check(args.onnx, args.check, args.pairs)
    if args.time:
        time_inference(args.onnx, args.time, args.threads)


if __name__ == "__main__":
    main()
