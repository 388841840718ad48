#!/usr/bin/env python3
"""PyTorch reference for pav's white-box step: YOLOv3-tiny from the same darknet cfg and weights
(batch norm folded, weights frozen), timed on the CPU as `pav bench-step` times pav: forward with
the loss, and forward + backward to the input. Prints CSV rows in bench-step's columns.

usage: torch_step.py CFG WEIGHTS --sizes 416,608 --threads 2 --repeats 20 [--header]
"""
import argparse, time
import numpy as np, torch, torch.nn.functional as F


def load(cfg_path, weights_path):
    """The layers of a darknet cfg with their folded weights, in order."""
    blocks = []
    for line in open(cfg_path):
        line = line.split('#')[0].strip()
        if not line:
            continue
        if line.startswith('['):
            blocks.append({'type': line[1:-1]})
        else:
            k, v = line.split('=', 1)
            blocks[-1][k.strip()] = v.strip()
    w = np.fromfile(weights_path, dtype=np.float32)
    major, minor = np.fromfile(weights_path, dtype=np.int32, count=2)
    at = 3 + (2 if major * 10 + minor >= 2 else 1)  # header: 3 ints and a 32- or 64-bit counter
    layers, chans, c = [], [], 3

    def take(n):
        nonlocal at
        at += n
        return w[at - n:at]

    for b in blocks[1:]:
        t = b['type']
        if t == 'convolutional':
            f, k, s = int(b['filters']), int(b['size']), int(b['stride'])
            pad = (k - 1) // 2 if int(b.get('pad', 0)) else 0
            if int(b.get('batch_normalize', 0)):
                beta, gamma, mean, var = take(f), take(f), take(f), take(f)
                kern = take(f * c * k * k).reshape(f, c, k, k)
                scale = gamma / np.sqrt(var + 1e-6)
                kern, bias = kern * scale[:, None, None, None], beta - mean * scale
            else:
                bias = take(f)
                kern = take(f * c * k * k).reshape(f, c, k, k)
            layers.append(('conv', torch.tensor(kern.copy()), torch.tensor(bias.copy()), s, pad,
                           b.get('activation') == 'leaky'))
            c = f
        elif t == 'maxpool':
            layers.append(('pool', int(b['size']), int(b['stride'])))
        elif t == 'upsample':
            layers.append(('up', int(b['stride'])))
        elif t == 'route':
            src = [int(x) for x in b['layers'].split(',')]
            src = [i if i >= 0 else len(layers) + i for i in src]
            layers.append(('route', src))
            c = sum(chans[i] for i in src)
        elif t == 'yolo':
            layers.append(('yolo',))
        chans.append(c)
    assert at == len(w), f'{weights_path}: {len(w) - at} weights left over'
    return layers


def forward(layers, x):
    outs, heads = [], []
    for m in layers:
        if m[0] == 'conv':
            x = F.conv2d(x, m[1], m[2], m[3], m[4])
            x = F.leaky_relu(x, 0.1) if m[5] else x
        elif m[0] == 'pool':
            k, s = m[1], m[2]
            # darknet pads k − 1 at the end with values that never win
            x = F.max_pool2d(F.pad(x, (0, k - 1, 0, k - 1), value=float('-inf')), k, s)
        elif m[0] == 'up':
            x = F.interpolate(x, scale_factor=m[1], mode='nearest')
        elif m[0] == 'route':
            x = torch.cat([outs[i] for i in m[1]], 1)
        elif m[0] == 'yolo':
            heads.append(x)
        outs.append(x)
    return heads


def loss(heads):
    # objectness × car confidence summed: its backward costs what pav's loss does
    total = 0
    for h in heads:
        n, ch, hh, ww = h.shape
        v = h.view(n, 3, ch // 3, hh, ww)
        total = total + (torch.sigmoid(v[:, :, 4]) * torch.sigmoid(v[:, :, 7])).sum()
    return total


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('cfg')
    ap.add_argument('weights')
    ap.add_argument('--sizes', default='416,608')
    ap.add_argument('--threads', type=int, default=2)
    ap.add_argument('--repeats', type=int, default=20)
    ap.add_argument('--header', action='store_true')
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    layers = load(a.cfg, a.weights)
    if a.header:
        print('backend,size,threads,repeats,forward_ms,forward_backward_ms,step_forward_ms,step_backward_ms,loss')
    for size in [int(s) for s in a.sizes.split(',')]:
        yy, xx = np.mgrid[0:size, 0:size]
        img = np.stack([0.5 + 0.4 * np.sin(xx * 0.05 + c) * np.cos(yy * 0.03) for c in range(3)])
        x0 = torch.tensor(img[None].astype(np.float32))
        fwd, step, sf, sb = [], [], [], []
        for r in range(3 + a.repeats):
            t = time.perf_counter()
            with torch.no_grad():
                loss(forward(layers, x0))
            t1 = time.perf_counter()
            x = x0.clone().requires_grad_(True)
            l = loss(forward(layers, x))
            t2 = time.perf_counter()
            l.backward()
            _ = x.grad
            t3 = time.perf_counter()
            if r >= 3:
                fwd.append(t1 - t); step.append(t3 - t1); sf.append(t2 - t1); sb.append(t3 - t2)
        med = lambda v: 1e3 * float(np.median(v))
        print(f'PyTorch {torch.__version__},{size},{a.threads},{a.repeats},{med(fwd):.3f},{med(step):.3f},{med(sf):.3f},{med(sb):.3f},sum obj×car')


if __name__ == '__main__':
    main()
