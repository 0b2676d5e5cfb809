"""PyTorch mirror of the DNO step that `mogen bench prior` times.

The same maths, op for op, on the same weights (read from our `prior.safetensors`):
DDIM-10 (eta = 0) over MDM's cosine schedule, unrolled from the optimised noise z through
the frozen MDM denoiser (post-LN transformer encoder, x0 prediction, the empty prompt's
condition as mogen's sentence encoder gives it, read from the dump's `text.npy`); de-normalisation; HumanML3D's `recover_from_ric`; bones re-scaled to the
file's rest skeleton; the loss (mean joint height, metres) standing in for a task's
constraint loss; backward to z; one Adam step (lr 0.05). Weights are frozen
(`requires_grad=False`), as in our fused layer that forms no weight gradient.

    python dno_step.py --prior fixtures/model/prior.safetensors --check DUMP_DIR
    python dno_step.py --prior fixtures/model/prior.safetensors --text DUMP_DIR/text.npy --batches 1,2,8

`--check` compares the joints, loss and gradient of one batch-1 step with the files that
`mogen bench prior --dump DUMP_DIR` wrote, and exits 1 when they differ. The timing run
prints one JSON object per batch size (median seconds over `--reps` steps after a warm-up).
"""

import argparse
import json
import math
import resource
import struct
import sys
import time

import numpy as np
import torch

# HumanML3D's 22-joint tree: the parent of each joint (-1 for the pelvis).
PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19]
NUM_JOINTS = 22
TIMESTEPS = 1000
BONE_EPS_M2 = 1e-12


def load_safetensors(path):
    """Tensors (float32 numpy; F16 ones, such as the caption table, widened) and metadata of a
    safetensors file."""
    with open(path, "rb") as f:
        n = struct.unpack("<Q", f.read(8))[0]
        header = json.loads(f.read(n))
        data = f.read()
    meta = header.pop("__metadata__", {})
    tensors = {}
    for name, info in header.items():
        dtype = {"F32": np.float32, "F16": np.float16}.get(info["dtype"])
        if dtype is None:
            raise ValueError(f"{name}: dtype {info['dtype']}, expected F32 or F16")
        start, end = info["data_offsets"]
        tensors[name] = np.frombuffer(data[start:end], dtype=dtype).reshape(info["shape"]).astype(np.float32)
    return tensors, meta


def sinusoidal_table(max_len, d):
    """MDM's positional table, computed in f32 as our `model::sinusoidal_table`."""
    rate = np.float32(-math.log(10000.0) / d)
    div = np.exp(np.arange(0, d, 2, dtype=np.float32) * rate).astype(np.float32)
    arg = np.arange(max_len, dtype=np.float32)[:, None] * div[None, :]
    pe = np.zeros((max_len, d), dtype=np.float32)
    pe[:, 0::2] = np.sin(arg)
    pe[:, 1::2] = np.cos(arg)
    return pe


def cosine_alphas_cumprod(steps=TIMESTEPS, s=0.008, max_beta=0.999):
    """ᾱ_t of the cosine schedule, recomputed from the clipped betas in f64."""
    abar = lambda t: math.cos((t + s) / (1 + s) * math.pi / 2) ** 2
    betas = [min(1 - abar((i + 1) / steps) / abar(i / steps), max_beta) for i in range(steps)]
    return np.cumprod(1.0 - np.array(betas, dtype=np.float64))


def respaced(steps):
    """MDM's "ddimK": range(0, T, s) for the smallest stride s giving K timesteps."""
    for stride in range(1, TIMESTEPS):
        if -(-TIMESTEPS // stride) == steps:
            return list(range(0, TIMESTEPS, stride))
    raise ValueError(f"no stride gives {steps} steps")


class Mirror:
    def __init__(self, path, ddim_steps=10, frames=100):
        w, meta = load_safetensors(path)
        cfg = json.loads(meta["mdm_config"])
        if cfg.get("prediction", "x0") != "x0":
            raise ValueError("the mirror covers x0-predicting priors only")
        self.heads, self.layers, self.d = cfg["num_heads"], cfg["num_layers"], cfg["latent_dim"]
        self.text_dim = cfg["text_dim"]
        t = lambda name: torch.from_numpy(w[name].copy())
        self.w = {k: t(k) for k in w}
        self.mean, self.std = t("normalization.mean"), t("normalization.std")
        rest = json.loads(meta["rest_skeleton"])["bone_lengths_m"]
        self.bone_lengths = torch.tensor(rest, dtype=torch.float32).reshape(NUM_JOINTS, 1)
        self.pe = torch.from_numpy(sinusoidal_table(frames + 1 + 1000, self.d))
        abar = cosine_alphas_cumprod()
        self.timesteps = respaced(ddim_steps)
        self.abar = [float(abar[t]) for t in self.timesteps]
        ancestry = np.zeros((NUM_JOINTS, NUM_JOINTS), dtype=np.float32)
        for j in range(NUM_JOINTS):
            k = j
            while k != 0:
                ancestry[k, j] = 1.0
                k = PARENTS[k]
        self.ancestry = torch.from_numpy(ancestry)
        self.parents = torch.tensor([max(p, 0) for p in PARENTS])

    def linear(self, x, name):
        return torch.nn.functional.linear(x, self.w[name + ".weight"], self.w[name + ".bias"])

    def layer(self, h, i):
        p = f"seqTransEncoder.layers.{i}."
        b, s, d = h.shape
        hd = d // self.heads
        qkv = torch.nn.functional.linear(h, self.w[p + "self_attn.in_proj_weight"], self.w[p + "self_attn.in_proj_bias"])
        q, k, v = qkv.split(d, dim=-1)
        heads = lambda x: x.reshape(b, s, self.heads, hd).transpose(1, 2)
        probs = torch.softmax(heads(q) @ heads(k).transpose(-1, -2) / math.sqrt(hd), dim=-1)
        ctx = (probs @ heads(v)).transpose(1, 2).reshape(b, s, d)
        attn = self.linear(ctx, p + "self_attn.out_proj")
        ln = lambda x, n: torch.nn.functional.layer_norm(x, (d,), self.w[n + ".weight"], self.w[n + ".bias"], 1e-5)
        h = ln(h + attn, p + "norm1")
        ff = self.linear(torch.nn.functional.gelu(self.linear(h, p + "linear1")), p + "linear2")
        return ln(h + ff, p + "norm2")

    def predict_x0(self, x, t, text):
        b, frames, _ = x.shape
        te = self.pe[t].expand(b, -1)
        t_emb = self.linear(torch.nn.functional.silu(self.linear(te, "embed_timestep.time_embed.0")), "embed_timestep.time_embed.2")
        cond = t_emb + self.linear(text, "embed_text")
        h = torch.cat([cond.unsqueeze(1), self.linear(x, "input_process.poseEmbedding")], dim=1)
        h = h + self.pe[: frames + 1]
        for i in range(self.layers):
            h = self.layer(h, i)
        return self.linear(h[:, 1:], "output_process.poseFinal")

    def sample(self, z, text):
        """DDIM (eta = 0) from z at the last spaced timestep down to t = 0; the model's x̂0."""
        x = z
        for k in reversed(range(len(self.timesteps))):
            x0 = self.predict_x0(x, self.timesteps[k], text)
            if k == 0:
                return x0
            a_from, a_to = self.abar[k], self.abar[k - 1]
            c_x = math.sqrt((1 - a_to) / (1 - a_from))
            c_0 = math.sqrt(a_to) - c_x * math.sqrt(a_from)
            x = x * c_x + x0 * c_0
        return x

    def joints(self, normalized):
        f = normalized * self.std + self.mean
        b, frames, _ = f.shape
        exclusive = torch.triu(torch.ones(frames, frames), diagonal=1)
        yaw = 2.0 * (f[..., 0] @ exclusive)
        cos, sin = torch.cos(yaw).unsqueeze(-1), torch.sin(yaw).unsqueeze(-1)
        lin = torch.cat([torch.zeros(b, 1, 2), f[:, :-1, 1:3]], dim=1)
        vx, vz = lin[..., 0:1], lin[..., 1:2]
        wx, wz = vx * cos - vz * sin, vx * sin + vz * cos
        inclusive = exclusive + torch.eye(frames)
        root_x = (wx.squeeze(-1) @ inclusive).unsqueeze(-1)
        root_z = (wz.squeeze(-1) @ inclusive).unsqueeze(-1)
        root = torch.cat([root_x, f[..., 3:4], root_z], dim=-1).unsqueeze(2)
        ric = f[..., 4 : 4 + 63].reshape(b, frames, NUM_JOINTS - 1, 3)
        px, py, pz = ric[..., 0:1], ric[..., 1:2], ric[..., 2:3]
        c4, s4 = cos.unsqueeze(-1), sin.unsqueeze(-1)
        jx = px * c4 - pz * s4 + root_x.unsqueeze(2)
        jz = px * s4 + pz * c4 + root_z.unsqueeze(2)
        joints = torch.cat([root, torch.cat([jx, py, jz], dim=3)], dim=2)
        # Bones re-scaled to the rest skeleton, summed down the tree from the pelvis.
        v = joints - joints[:, :, self.parents]
        scaled = v / torch.sqrt((v * v).sum(-1, keepdim=True) + BONE_EPS_M2) * self.bone_lengths
        summed = scaled.transpose(2, 3) @ self.ancestry
        return summed.transpose(2, 3) + joints[:, :, 0:1]

    def loss(self, z, text):
        return self.joints(self.sample(z, text))[..., 1].mean()


def check(mirror, folder):
    """Compares one batch-1 step with `mogen bench prior --dump` files; True when they agree."""
    z = torch.from_numpy(np.load(f"{folder}/z.npy")).float().requires_grad_(True)
    text = torch.from_numpy(np.load(f"{folder}/text.npy")).float()
    joints = mirror.joints(mirror.sample(z, text))
    loss = joints[..., 1].mean()
    loss.backward()
    ref = {n: np.load(f"{folder}/{n}.npy") for n in ("joints", "loss", "grad")}
    joint_err = float(np.abs(joints.detach().numpy() - ref["joints"]).max())
    loss_err = abs(loss.item() - float(ref["loss"][0]))
    grad_scale = float(np.abs(ref["grad"]).max())
    grad_err = float(np.abs(z.grad.numpy() - ref["grad"]).max()) / grad_scale
    ok = joint_err < 1e-3 and loss_err < 1e-4 and grad_err < 1e-2
    print(json.dumps({"check": "ok" if ok else "MISMATCH", "max_joint_error_m": joint_err,
                      "loss_error_m": loss_err, "max_gradient_error_relative": grad_err}))
    return ok


def time_steps(mirror, batch, frames, reps, text_file):
    torch.manual_seed(0)
    z = torch.randn(batch, frames, 263).requires_grad_(True)
    text = torch.from_numpy(np.load(text_file)).float().expand(batch, -1)
    adam = torch.optim.Adam([z], lr=0.05)
    times = []
    for i in range(reps + 1):
        start = time.perf_counter()
        adam.zero_grad(set_to_none=True)
        mirror.loss(z, text).backward()
        adam.step()
        if i > 0:
            times.append(time.perf_counter() - start)
    return float(np.median(times))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--prior", required=True)
    ap.add_argument("--check", help="folder written by `mogen bench prior --dump`")
    ap.add_argument("--text", help="the empty prompt's condition `[1, text_dim]` (`text.npy` of a dump)")
    ap.add_argument("--batches", default="1,2,8")
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--reps", type=int, default=10)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    mirror = Mirror(args.prior, frames=args.frames)
    if args.check:
        sys.exit(0 if check(mirror, args.check) else 1)
    if not args.text:
        ap.error("--text is required for timing")
    for batch in [int(b) for b in args.batches.split(",")]:
        step = time_steps(mirror, batch, args.frames, args.reps, args.text)
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        print(json.dumps({"batch": batch, "threads": torch.get_num_threads(), "dno_step_s": step,
                          "peak_rss_mib": rss, "torch": torch.__version__,
                          "cpu_capability": torch.backends.cpu.get_cpu_capability()}), flush=True)


if __name__ == "__main__":
    main()
