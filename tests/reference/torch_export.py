"""Train a small MLP controller in PyTorch and export it with torch.onnx.export.

Makes the committed fixtures tests/reference/di_tanh.onnx and di_relu.onnx that
tests/onnx_out_in.rs imports, certifies and exports with the `trainer` binary (CI runs no
Python). The network is the usual PyTorch way of writing a controller: input scaling
(x - mean) / std, a few Linear layers with tanh (or ReLU), output scaling y * scale + offset,
all as registered buffers, so torch.onnx.export writes Sub/Div, Gemm, Tanh/Relu, Mul/Add.
The file is used unedited.

Usage (double integrator of configs/double_integrator.toml, labels from `trainer sample`):

    trainer sample --config configs/double_integrator.toml --out di.bin   # writes di.csv
    python tests/reference/torch_export.py di.csv tests/reference/di_tanh.onnx --act tanh \
        --hidden 32 32 --steps 8000
    python tests/reference/torch_export.py di.csv tests/reference/di_relu.onnx --act relu

The fixtures were made with torch 1.12.1 (the TorchScript-based exporter, opset 13).
"""

import argparse
import csv

import torch
from torch import nn


class Controller(nn.Module):
    def __init__(self, nx, nu, hidden, act, x_lo, x_hi, u_lo, u_hi):
        super().__init__()
        self.register_buffer("x_mean", (x_lo + x_hi) / 2)
        self.register_buffer("x_std", (x_hi - x_lo) / 2)
        self.register_buffer("u_scale", (u_hi - u_lo) / 2)
        self.register_buffer("u_offset", (u_hi + u_lo) / 2)
        layers, w = [], nx
        for h in hidden:
            layers += [nn.Linear(w, h), nn.Tanh() if act == "tanh" else nn.ReLU()]
            w = h
        layers.append(nn.Linear(w, nu))
        self.net = nn.Sequential(*layers)

    def forward(self, x):
        return self.net((x - self.x_mean) / self.x_std) * self.u_scale + self.u_offset


def main():
    p = argparse.ArgumentParser()
    p.add_argument("csv")
    p.add_argument("out")
    p.add_argument("--act", choices=["tanh", "relu"], default="tanh")
    p.add_argument("--hidden", type=int, nargs="+", default=[16, 16])
    p.add_argument("--steps", type=int, default=3000)
    a = p.parse_args()
    torch.manual_seed(0)
    rows = list(csv.DictReader(open(a.csv)))
    rows = [r for r in rows if r["status"] == "converged"]
    xs = torch.tensor([[float(r["x1"]), float(r["x2"])] for r in rows])
    us = torch.tensor([[float(r["u1"])] for r in rows])
    model = Controller(
        2, 1, a.hidden, a.act,
        xs.min(0).values, xs.max(0).values,
        torch.tensor([-1.0]), torch.tensor([1.0]),
    )
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, a.steps)
    for step in range(a.steps):
        opt.zero_grad()
        loss = ((model(xs) - us) ** 2).mean()
        loss.backward()
        opt.step()
        sched.step()
    print(f"final MSE {loss.item():.3e}, max error {(model(xs) - us).abs().max().item():.3e}")
    model.eval()
    torch.onnx.export(
        model,
        torch.zeros(1, 2),
        a.out,
        input_names=["x"],
        output_names=["u"],
        dynamic_axes={"x": {0: "batch"}, "u": {0: "batch"}},
        opset_version=13,
    )


if __name__ == "__main__":
    main()
