"""Train the landmark detector on a pool of scenes and export it to ONNX.

Usage (in the training venv, torch 2.13.0 CPU; see docs/detector.md)::

    PYTHONPATH=. .venv/bin/python -m training.sim_pool --out /tmp/det/sim_pool.npz
    /work/venv-train/bin/python -m training.train --scales 3 --pool /tmp/det/sim_pool.npz \
        --max-steps 3000 --minutes 60 --out tracker/models/landmark_yolo_tiny3.onnx

Anchors are fitted by k-means (1 - IoU distance) to the pool's boxes; the pool (built once,
seeded) is shared by every variant so that a comparison between the 2-scale and 3-scale
networks sees exactly the same data. A run stops at ``--max-steps`` or after ``--minutes``,
whichever comes first; the learning-rate schedule follows the larger of the two fractions.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812

from training.args import positive
from training.model import TinyYolo
from training.synth_data import CATEGORIES

STRIDES = {2: (16, 32), 3: (8, 16, 32)}
OBJ_BALANCE = {8: 4.0, 16: 1.0, 32: 0.4}  # objectness weight per stride (YOLOv5)


def kmeans_anchors(wh: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """k-means on box sizes with distance 1 - IoU (boxes aligned at a corner); sorted by area."""
    centres = wh[rng.choice(len(wh), k, replace=False)].copy()
    for _ in range(100):
        inter = np.minimum(wh[:, None, 0], centres[None, :, 0]) * np.minimum(
            wh[:, None, 1], centres[None, :, 1])
        iou = inter / (wh.prod(1)[:, None] + centres.prod(1)[None] - inter)
        assign = iou.argmax(1)
        new = np.array([np.median(wh[assign == j], 0) if np.any(assign == j) else centres[j]
                        for j in range(k)])
        if np.allclose(new, centres):
            break
        centres = new
    return centres[np.argsort(centres.prod(1))].round(1)


def initial_anchors(init: Path | None, wh: np.ndarray, heads: int) -> list[np.ndarray]:
    """The anchors a fine-tune started from (metadata of the ONNX beside ``init``), else
    fitted to the pool's box sizes."""
    if init is not None and init.with_suffix(".onnx").is_file():
        import onnx

        meta = {p.key: p.value for p in onnx.load(str(init.with_suffix(".onnx"))).metadata_props}
        return [np.array(a, np.float64) for a in json.loads(meta["anchors"])]
    return list(kmeans_anchors(wh, 3 * heads, np.random.default_rng(7)).reshape(heads, 3, 2))


def load_pools(paths: list[Path], size: int) -> tuple[np.ndarray, np.ndarray]:
    """Images and target rows (image, class, cx, cy, w, h) of one or more pools, joined."""
    images, targets = [], []
    for path in paths:
        if not path.is_file():
            raise SystemExit(f"{path}: no such pool (build it: python -m training.sim_pool)")
        data = np.load(path)
        if data["images"].shape[1:3] != (size, size):
            raise SystemExit(f"{path}: images are {data['images'].shape[1:3]}, not {size}")
        t = data["targets"].copy()
        t[:, 0] += sum(len(i) for i in images)
        images.append(data["images"])
        targets.append(t)
    return np.concatenate(images), np.concatenate(targets)


def box_giou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Generalised IoU of (cx, cy, w, h) box rows."""
    a1, a2 = a[:, :2] - a[:, 2:] / 2, a[:, :2] + a[:, 2:] / 2
    b1, b2 = b[:, :2] - b[:, 2:] / 2, b[:, :2] + b[:, 2:] / 2
    inter = (torch.min(a2, b2) - torch.max(a1, b1)).clamp(0).prod(1)
    union = a[:, 2:].prod(1) + b[:, 2:].prod(1) - inter + 1e-9
    hull = (torch.max(a2, b2) - torch.min(a1, b1)).prod(1) + 1e-9
    iou = inter / union
    return iou - (hull - union) / hull


def yolo_loss(outputs: list[torch.Tensor], targets: torch.Tensor, anchors: list[np.ndarray],
              strides: tuple[int, ...], nc: int) -> torch.Tensor:
    """YOLOv5-style loss: anchors matched by size ratio < 4, centre cell plus 2 neighbours.

    Decoding: xy = 2*sig(t) - 0.5 + cell; wh = (2*sig(t))^2 * anchor.
    targets rows: (image, class, cx, cy, w, h) in input pixels.
    """
    bs = outputs[0].shape[0]
    l_box = torch.zeros(()); l_obj = torch.zeros(()); l_cls = torch.zeros(())  # noqa: E702
    for out, anc_np, s in zip(outputs, anchors, strides, strict=True):
        na, gh, gw = len(anc_np), out.shape[2], out.shape[3]
        p = out.view(bs, na, 5 + nc, gh, gw).permute(0, 1, 3, 4, 2)
        tobj = torch.zeros(p.shape[:4])
        anc = torch.tensor(anc_np, dtype=torch.float32) / s
        if len(targets):
            t = targets.clone()
            t[:, 2:] /= s
            r = t[None, :, 4:6] / anc[:, None]  # (na, nt, 2)
            ok = torch.max(r, 1 / r).max(2).values < 4.0
            ai = torch.arange(na)[:, None].expand(na, len(t))[ok]
            tt = t[None].expand(na, -1, -1)[ok]
            gxy = tt[:, 2:4]
            frac = gxy % 1.0
            offs = [torch.zeros_like(gxy)]
            sel = [torch.ones(len(tt), dtype=torch.bool)]
            for dim, d in ((0, -1), (1, -1), (0, 1), (1, 1)):
                o = torch.zeros_like(gxy)
                o[:, dim] = d
                near = (frac[:, dim] < 0.5) & (gxy[:, dim] > 1) if d < 0 else (
                    (frac[:, dim] > 0.5) & (gxy[:, dim] < (gw, gh)[dim] - 1))
                offs.append(o)
                sel.append(near)
            cells, idx_t, idx_a = [], [], []
            for o, m in zip(offs, sel, strict=True):
                cells.append((gxy[m] + o[m]).floor().long())
                idx_t.append(tt[m])
                idx_a.append(ai[m])
            cell = torch.cat(cells)
            tsel = torch.cat(idx_t)
            asel = torch.cat(idx_a)
            cell[:, 0].clamp_(0, gw - 1)
            cell[:, 1].clamp_(0, gh - 1)
            b = tsel[:, 0].long()
            ps = p[b, asel, cell[:, 1], cell[:, 0]]
            pxy = ps[:, :2].sigmoid() * 2 - 0.5
            pwh = (ps[:, 2:4].sigmoid() * 2) ** 2 * anc[asel]
            giou = box_giou(torch.cat([pxy, pwh], 1),
                            torch.cat([tsel[:, 2:4] - cell, tsel[:, 4:6]], 1))
            l_box = l_box + (1.0 - giou).mean()
            tobj[b, asel, cell[:, 1], cell[:, 0]] = giou.detach().clamp(0).to(tobj.dtype)
            tcls = F.one_hot(tsel[:, 1].long(), nc).float()
            l_cls = l_cls + F.binary_cross_entropy_with_logits(ps[:, 5:], tcls)
        l_obj = l_obj + OBJ_BALANCE[s] * F.binary_cross_entropy_with_logits(p[..., 4], tobj)
    return (0.05 * l_box + 1.0 * l_obj + 0.3 * l_cls) * bs


def export_onnx(model: TinyYolo, path: Path, anchors: list[np.ndarray],
                strides: tuple[int, ...], input_size: int, info: dict) -> None:
    """Export with opset 17 and IR version <= 10, with decoding metadata for the detector."""
    import onnx

    model.eval()
    dummy = torch.zeros(1, 3, input_size, input_size)
    names = [f"out{s}" for s in strides]
    torch.onnx.export(model, (dummy,), str(path), opset_version=17, input_names=["images"],
                      output_names=names, dynamo=False)
    m = onnx.load(str(path))
    m.ir_version = min(m.ir_version, 10)
    meta = {"format": "landmark-companion-yolo", "version": "1",
            "names": json.dumps(list(CATEGORIES)), "strides": json.dumps(list(strides)),
            "anchors": json.dumps([a.tolist() for a in anchors]),
            "box_decoding": "yolov5", "channel_order": "bgr", "scale": "1/255",
            "training": json.dumps(info)}
    del m.metadata_props[:]
    for k, v in meta.items():
        m.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(m)
    onnx.save(m, str(path))


def lr_at(frac: float, base: float, warm: float = 0.03) -> float:
    """Linear warm-up then cosine decay to 5% of ``base`` over the budget fraction ``frac``."""
    if frac < warm:
        return base * frac / warm
    t = min(1.0, (frac - warm) / (1 - warm))
    return base * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * t)))


def parse_args() -> argparse.Namespace:
    """Command-line options."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scales", type=int, choices=(2, 3), default=3)
    ap.add_argument("--minutes", type=float, default=25.0, help="wall-clock training budget")
    ap.add_argument("--max-steps", type=positive, default=100000)
    ap.add_argument("--batch", type=positive, default=16)
    ap.add_argument("--lr", type=float, default=2e-3)
    ap.add_argument("--train-size", type=int, default=256)
    ap.add_argument("--input-size", type=int, default=416, help="exported input size")
    ap.add_argument("--pool", type=Path, action="append", required=True,
                    help="images + targets .npz (python -m training.sim_pool); repeatable")
    ap.add_argument("--threads", type=positive, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--init", type=Path, default=None,
                    help="start from these weights (.pt state dict of the same variant)")
    return ap.parse_args()


def main() -> None:
    """Fit anchors, build/load the scene pool, train for the budget, export ONNX."""
    args = parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    images, targets = load_pools(args.pool, args.train_size)
    strides = STRIDES[args.scales]
    anchors = initial_anchors(args.init, targets[:, 4:6], len(strides))
    print("anchors", [a.tolist() for a in anchors], flush=True)
    model = TinyYolo(len(CATEGORIES), 3, args.scales == 3)
    if args.init is not None:
        model.load_state_dict(torch.load(args.init, weights_only=True))
    n_params = sum(p.numel() for p in model.parameters())
    print("params", n_params, flush=True)
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=5e-4)
    by_image = {int(i): targets[targets[:, 0] == i] for i in np.unique(targets[:, 0])}
    t0, step, budget = time.monotonic(), 0, args.minutes * 60.0
    model.train()
    while True:
        frac = max((time.monotonic() - t0) / budget, step / args.max_steps)
        if frac >= 1.0:
            break
        for g in opt.param_groups:
            g["lr"] = lr_at(frac, args.lr)
        idx = rng.choice(len(images), args.batch, replace=False)
        batch = images[idx].astype(np.float32) / 255.0
        rows = []
        for j, i in enumerate(idx):
            t = by_image.get(int(i), np.zeros((0, 6), np.float32)).copy()
            t[:, 0] = j
            if rng.random() < 0.5:  # horizontal flip
                batch[j] = batch[j, :, ::-1]
                t[:, 2] = args.train_size - t[:, 2]
            rows.append(t)
        x = torch.from_numpy(np.ascontiguousarray(batch.transpose(0, 3, 1, 2)))
        tg = torch.from_numpy(np.concatenate(rows))
        loss = yolo_loss(model(x), tg, anchors, strides, len(CATEGORIES))
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 10.0)
        opt.step()
        step += 1
        if step % 20 == 0:
            print(f"step {step} t={time.monotonic() - t0:.0f}s lr={lr_at(frac, args.lr):.5f} "
                  f"loss={loss.item():.3f}", flush=True)
    info = {"scales": args.scales, "steps": step, "batch": args.batch,
            "minutes": round((time.monotonic() - t0) / 60, 1), "train_size": args.train_size,
            "pool": f"{'+'.join(p.name for p in args.pool)} ({len(images)} images)",
            "seed": args.seed,
            "params": n_params,
            "init": args.init.name if args.init else None}
    print("done", info, flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    torch.save(model.state_dict(), args.out.with_suffix(".pt"))
    export_onnx(model, args.out, anchors, strides, args.input_size, info)
    print("exported", args.out, args.out.stat().st_size, flush=True)


if __name__ == "__main__":
    main()
