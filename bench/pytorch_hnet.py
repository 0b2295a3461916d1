"""H-Net in PyTorch, for timing against Burn (docs/benchmarks.md).

The same network as crates/hnet-model (paper section II.B): shared encoder-decoder with 32
filters, 4 levels, transposed 3x3 stride-2 upsampling, global-average-pooled bottleneck and
decoder features of both views into a 64-32-3 force head; BCE x2 + MSE loss; RMSprop at 1e-4.

Measures, on the CPU with a fixed thread count:
  - a training step (forward, backward, optimizer) on a batch of B stereo pairs,
  - inference latency of one stereo pair.

Usage: python bench/pytorch_hnet.py --size 64 --batch 8 --threads 2 [--json]
"""

import argparse
import json
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


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
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
