"""H-Net in PyTorch, for timing against Burn (docs/benchmarks.md).

The same network as crates/hnet-model (paper section II.B): shared encoder-decoder with 32
filters, 4 levels, transposed 3x3 stride-2 upsampling, global-average-pooled bottleneck and
decoder features of both views into a 64-32-3 force head; BCE x2 + MSE loss; RMSprop at 1e-4.

Measures, on the CPU with a fixed thread count:
  - a training step (forward, backward, optimizer) on a batch of B stereo pairs,
  - inference latency of one stereo pair.

With --layers, instead times each convolution of the shared encoder-decoder at the shapes a
training step gives it (forward, weight gradient, input gradient), as `hnet bench layers` does.

With --onnx PATH, instead exports the network for inference to ONNX: one stereo pair (batch 1) of
--size x --size RGB images in [0, 1] in (`view_a`, `view_b`, each [1, 3, H, W]), the two mask
probabilities (`mask_a`, `mask_b`, [1, 1, H, W], after the sigmoid) and the force (`force`,
[1, 3]) out, as the page's `HNet::predict_async` computes them; weights from seed 0 (the time
does not depend on them). end2end/ort-bench/ times it in ONNX Runtime Web (bench/README.md).

Usage: python bench/pytorch_hnet.py --size 64 --batch 8 --threads 2 [--layers] [--json]
       python bench/pytorch_hnet.py --size 64 --onnx PATH
"""

import argparse
import json
import os
import time

import torch
from torch import nn


class DoubleConv(nn.Module):
    def __init__(self, cin, f):
        super().__init__()
        self.first = nn.Conv2d(cin, f, 3, padding=1)
        self.second = nn.Conv2d(f, f, 3, padding=1)

    def forward(self, x):
        return torch.relu(self.second(torch.relu(self.first(x))))


class UpBlock(nn.Module):
    def __init__(self, f):
        super().__init__()
        self.up = nn.ConvTranspose2d(f, f, 3, stride=2, padding=1, output_padding=1)
        self.conv = DoubleConv(2 * f, f)

    def forward(self, x, skip):
        return self.conv(torch.cat([self.up(x), skip], 1))


class HNet(nn.Module):
    def __init__(self, filters=32, depth=4):
        super().__init__()
        self.encoder = nn.ModuleList(
            [DoubleConv(3 if i == 0 else filters, filters) for i in range(depth)]
        )
        self.bottleneck = DoubleConv(filters, filters)
        self.decoder = nn.ModuleList([UpBlock(filters) for _ in range(depth)])
        self.head = nn.Conv2d(filters, 1, 1)
        features = 2 * (depth + 1) * filters
        self.force = nn.Sequential(
            nn.Linear(features, 64), nn.ReLU(), nn.Linear(64, 32), nn.ReLU(), nn.Linear(32, 3)
        )

    def forward(self, a, b):
        batch = a.shape[0]
        x = torch.cat([a, b], 0)
        skips = []
        for block in self.encoder:
            x = block(x)
            skips.append(x)
            x = torch.max_pool2d(x, 2)
        x = self.bottleneck(x)
        pooled = [x.mean(dim=(2, 3))]
        for block, skip in zip(self.decoder, reversed(skips)):
            x = block(x, skip)
            pooled.append(x.mean(dim=(2, 3)))
        logits = self.head(x)
        pooled = torch.cat(pooled, 1)
        features = torch.cat([pooled[:batch], pooled[batch:]], 1)
        return logits[:batch], logits[batch:], self.force(features)


def hnet_convolutions(size, filters=32, depth=4, in_channels=3):
    """The list of `hnet_convolutions` in crates/hnet-cli/src/bench/layers.rs:
    (name, transposed, channels_in, channels_out, kernel, input side, input gradient needed)."""
    f = filters
    layers = []
    for level in range(depth):
        cin = in_channels if level == 0 else f
        layers.append((f"encoder{level + 1}.first", False, cin, f, 3, size >> level, level > 0))
        layers.append((f"encoder{level + 1}.second", False, f, f, 3, size >> level, True))
    layers.append(("bottleneck.first", False, f, f, 3, size >> depth, True))
    layers.append(("bottleneck.second", False, f, f, 3, size >> depth, True))
    for block in range(depth):
        below = size >> (depth - block)
        layers.append((f"decoder{block + 1}.up", True, f, f, 3, below, True))
        layers.append((f"decoder{block + 1}.first", False, 2 * f, f, 3, 2 * below, True))
        layers.append((f"decoder{block + 1}.second", False, f, f, 3, 2 * below, True))
    layers.append(("head", False, f, 1, 1, size, True))
    return layers


def median_ms(runs, fn):
    fn()
    times = []
    for _ in range(max(runs, 1)):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1e3)
    return sorted(times)[len(times) // 2]


def time_layers(args):
    images = 2 * args.batch
    rows = []
    for name, transposed, cin, cout, k, side, input_grad in hnet_convolutions(args.size):
        if transposed:
            conv = nn.ConvTranspose2d(cin, cout, k, stride=2, padding=1, output_padding=1)
            out_side = 2 * side
        else:
            conv = nn.Conv2d(cin, cout, k, padding=k // 2)
            out_side = side
        x = torch.rand(images, cin, side, side)
        upstream = torch.rand(images, cout, out_side, out_side)

        def forward():
            with torch.no_grad():
                conv(x)

        def grad_of(tracked):
            # Only the timed tensor is tracked, as in `hnet bench layers`.
            conv.weight.requires_grad_(tracked == "weight")
            conv.bias.requires_grad_(False)
            xi = x.detach().requires_grad_(tracked == "input")
            target = conv.weight if tracked == "weight" else xi
            return lambda: torch.autograd.grad((conv(xi) * upstream).sum(), [target])

        def loss_only():
            y = torch.rand(images, cout, out_side, out_side, requires_grad=True)
            torch.autograd.grad((y * upstream).sum(), [y])

        loss_ms = median_ms(args.runs, loss_only) - median_ms(
            args.runs, lambda: torch.rand(images, cout, out_side, out_side)
        )
        forward_ms = median_ms(args.runs, forward)
        weight_ms = max(median_ms(args.runs, grad_of("weight")) - forward_ms - loss_ms, 0.0)
        input_ms = (
            max(median_ms(args.runs, grad_of("input")) - forward_ms - loss_ms, 0.0)
            if input_grad
            else None
        )
        rows.append(
            {
                "name": name,
                "channels_in": cin,
                "channels_out": cout,
                "input_size": [side, side],
                "forward_ms": forward_ms,
                "weight_grad_ms": weight_ms,
                "input_grad_ms": input_ms,
            }
        )
    return rows


def report_layers(args):
    rows = time_layers(args)
    totals = {
        f"total_{key}": sum(r[key] or 0.0 for r in rows)
        for key in ("forward_ms", "weight_grad_ms", "input_grad_ms")
    }
    framework = f"pytorch {torch.__version__}"
    if args.json:
        result = {"framework": framework, "size": args.size, "batch": args.batch,
                  "threads": args.threads, "layers": rows, **totals}
        print(json.dumps(result, indent=2))
        return
    print(f"{framework}: H-Net convolutions at {args.size}x{args.size}, {2 * args.batch} images "
          f"each, {args.threads} threads, median of {args.runs} runs (ms)")
    print(f"{'layer':<18} {'in -> out':>9} {'input':>11} {'forward':>8} {'weight grad':>12} "
          f"{'input grad':>11}")
    for r in rows:
        channels = f"{r['channels_in']} -> {r['channels_out']}"
        side = f"{r['input_size'][0]}x{r['input_size'][1]}"
        grad_in = "-" if r["input_grad_ms"] is None else f"{r['input_grad_ms']:.2f}"
        print(f"{r['name']:<18} {channels:>9} {side:>11} {r['forward_ms']:8.2f} "
              f"{r['weight_grad_ms']:12.2f} {grad_in:>11}")
    print(f"{'total':<40} {totals['total_forward_ms']:8.1f} {totals['total_weight_grad_ms']:12.1f} "
          f"{totals['total_input_grad_ms']:11.1f}")


class Inference(nn.Module):
    """H-Net as the page runs it: mask probabilities (sigmoid of the logits) and the force."""

    def __init__(self, model):
        super().__init__()
        self.model = model

    def forward(self, view_a, view_b):
        logits_a, logits_b, force = self.model(view_a, view_b)
        return torch.sigmoid(logits_a), torch.sigmoid(logits_b), force


# Every operator H-Net needs (Conv, ConvTranspose, MaxPool, ReduceMean, Gemm, ...) is in opset
# 18, which ONNX Runtime Web 1.30 runs (end2end/ort-bench); torch 2.15 would default to 20.
ONNX_OPSET = 18


def export_onnx(args):
    model = Inference(HNet()).eval()
    shape = (1, 3, args.size, args.size)
    a, b = torch.rand(shape), torch.rand(shape)
    os.makedirs(os.path.dirname(os.path.abspath(args.onnx)), exist_ok=True)
    torch.onnx.export(
        model,
        (a, b),
        args.onnx,
        input_names=["view_a", "view_b"],
        output_names=["mask_a", "mask_b", "force"],
        opset_version=ONNX_OPSET,
        dynamo=True,
        external_data=False,
        verbose=False,
    )
    params = sum(p.numel() for p in model.parameters())
    result = {"framework": f"pytorch {torch.__version__}", "onnx": args.onnx, "opset": ONNX_OPSET,
              "params": params, "size": args.size, "batch": 1}
    # Check the file against PyTorch where onnxruntime (Python) is installed.
    try:
        import onnxruntime
    except ImportError:
        onnxruntime = None
    if onnxruntime is not None:
        session = onnxruntime.InferenceSession(args.onnx, providers=["CPUExecutionProvider"])
        got = session.run(None, {"view_a": a.numpy(), "view_b": b.numpy()})
        with torch.no_grad():
            want = model(a, b)
        result["max_abs_diff_vs_pytorch"] = max(
            float((torch.from_numpy(g) - w).abs().max()) for g, w in zip(got, want)
        )
    if args.json:
        print(json.dumps(result, indent=2))
        return
    line = (f"wrote {args.onnx}: H-Net ({params} parameters), one {args.size}x{args.size} pair, "
            f"opset {ONNX_OPSET}")
    if "max_abs_diff_vs_pytorch" in result:
        line += f", max |ONNX Runtime - PyTorch| {result['max_abs_diff_vs_pytorch']:.2e}"
    print(line)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--layers", action="store_true")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--onnx", metavar="PATH", help="export the inference network to ONNX")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    if args.onnx:
        export_onnx(args)
        return
    if args.layers:
        report_layers(args)
        return
    model = HNet()
    params = sum(p.numel() for p in model.parameters())
    optimizer = torch.optim.RMSprop(model.parameters(), lr=1e-4, alpha=0.9, eps=1e-7)
    shape = (args.batch, 3, args.size, args.size)
    a, b = torch.rand(shape), torch.rand(shape)
    mask_a = (torch.rand(args.batch, 1, args.size, args.size) > 0.9).float()
    mask_b = (torch.rand(args.batch, 1, args.size, args.size) > 0.9).float()
    force = torch.rand(args.batch, 3) * 0.4
    bce = nn.BCEWithLogitsLoss()

    def step():
        optimizer.zero_grad()
        la, lb, f = model(a, b)
        loss = bce(la, mask_a) + bce(lb, mask_b) + nn.functional.mse_loss(f, force)
        loss.backward()
        optimizer.step()

    step()  # warm-up
    start = time.perf_counter()
    for _ in range(args.steps):
        step()
    train_step_s = (time.perf_counter() - start) / args.steps

    model.eval()
    one_a, one_b = torch.rand(1, 3, args.size, args.size), torch.rand(1, 3, args.size, args.size)
    with torch.no_grad():
        model(one_a, one_b)
        runs = 20
        start = time.perf_counter()
        for _ in range(runs):
            model(one_a, one_b)
        infer_s = (time.perf_counter() - start) / runs

    result = {
        "framework": f"pytorch {torch.__version__}",
        "params": params,
        "size": args.size,
        "batch": args.batch,
        "threads": args.threads,
        "train_step_s": train_step_s,
        "infer_pair_s": infer_s,
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(
            f"pytorch {torch.__version__}: {params} parameters, train step "
            f"(batch {args.batch}, {args.size}x{args.size}) {train_step_s * 1e3:.1f} ms, "
            f"inference per stereo pair {infer_s * 1e3:.1f} ms on {args.threads} threads"
        )


if __name__ == "__main__":
    main()
