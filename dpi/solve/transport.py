"""The light transport of the training views, recorded once: a data term without path tracing.

With the materials fixed, a rendered pixel is linear in the environment map's texels, I = T L
(per colour channel). `record_view` traces the paths of Mitsuba's `prb` integrator (camera ray,
then at every vertex next-event estimation towards the environment and a BSDF-sampled bounce,
both weighted by multiple importance sampling, up to `max_depth`), but where the integrator
multiplies a path's throughput by the map's radiance, it records (pixel, texel, throughput)
instead: the map's bilinear lookup (Mitsuba's own, see `texel_weights`) spreads each contribution
over its four texels. Next-event directions come from a fixed guide map (the current map with a
floor), not from the map T will be applied to, so T L is an unbiased render for every L.

The data term of dps is a sum of per-view foreground mean squares, so `record_transport` keeps only
its normal equations, per channel: G = sum_v T_v^T W_v T_v and b = sum_v T_v^T W_v y_v (W_v: the
view's loss weights). Then the data loss of all training views under any map is
L^T G L - 2 b^T L + k (milliseconds, memory (texels^2 x 3), independent of the pixel count) and
its gradient is 2 (G L - b). Each view's T at `spp` paths per pixel is noisy, so G carries the
variance of T L as a small ridge; `spp` sets it. T depends on the materials: `Transport.stale`
says when they have moved enough since the recording for a refresh.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import torch

from dpi.materials import MaterialTextures
from dpi.solve.problem import InverseProblem

GUIDE_FLOOR = 0.25
"""the guide map for next-event directions is the map plus this share of its mean: every texel keeps a
chance to be sampled, so T stays unbiased and useful for maps brighter elsewhere"""


@dataclass
class TransportSettings:
    """How the light transport is recorded and kept up to date (method_params.dps.transport)."""

    spp: int = 32
    """paths per pixel of a recording (its noise is the data term's ridge: more is closer, slower)"""
    refresh_tolerance: float = 0.02
    """re-record when the materials moved by more than this since the recording (RMS over the textures)"""


def texel_weights(directions: np.ndarray, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel indices (n, 4) into an (H, 2H) map and bilinear weights (n, 4) of Mitsuba's envmap lookup at
    world directions (n, 3): columns at u = atan2(x, -z) / 2pi are texel centres, rows at v = acos(y) / pi
    span the poles (row r at v = r / (H - 1)), azimuth wraps (dpi.envmap documents the map's layout)."""
    width = 2 * height
    d = np.asarray(directions, np.float64)
    u = np.mod(np.arctan2(d[:, 0], -d[:, 2]) / (2 * np.pi), 1.0)
    v = np.arccos(np.clip(d[:, 1], -1.0, 1.0)) / np.pi
    x = u * width - 0.5
    y = v * (height - 1)
    x0 = np.floor(x)
    y0 = np.minimum(np.floor(y), height - 2)
    fx, fy = x - x0, y - y0
    cols = np.stack([x0, x0 + 1]).astype(np.int64) % width
    rows = np.stack([y0, y0 + 1]).astype(np.int64)
    index = np.stack([rows[0] * width + cols[0], rows[0] * width + cols[1],
                      rows[1] * width + cols[0], rows[1] * width + cols[1]], axis=1)
    weight = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], axis=1)
    return index, weight


@dataclass
class ViewTransport:
    """T of one view: per channel a sparse (foreground pixels x texels) matrix, and which pixels they are."""

    matrices: list[sp.csr_matrix]
    pixels: np.ndarray
    """flat indices (row-major in the (h, w) image) of the matrices' rows"""
    shape: tuple[int, int]

    def image(self, env: np.ndarray) -> np.ndarray:
        """The view's (h, w, 3) image under an (H, 2H, 3) map: T L on the foreground, 0 elsewhere."""
        flat = env.reshape(-1, 3)
        out = np.zeros((self.shape[0] * self.shape[1], 3))
        for c, matrix in enumerate(self.matrices):
            out[self.pixels, c] = matrix @ flat[:, c]
        return out.reshape(*self.shape, 3)


def guide_map(env: torch.Tensor) -> np.ndarray:
    """The next-event guide: the map plus GUIDE_FLOOR times its mean (positive everywhere)."""
    env = env.detach().double().clamp_min(0).numpy()
    return (env + GUIDE_FLOOR * max(float(env.mean()), 1e-12)).astype(np.float32)


def record_view(problem: InverseProblem, view: int, materials: MaterialTextures, guide: np.ndarray, spp: int,
                seed: int) -> ViewTransport:
    """T of one view's foreground pixels (module notes), `spp` paths per pixel, seeded."""
    renderer = problem.renderer
    mi = renderer.mi
    import drjit as dr

    renderer.set_scene(torch.from_numpy(guide), materials.albedo, materials.roughness, materials.metallic)
    scene, height = renderer.scene, renderer.env_height
    camera = renderer.cameras[view]
    w, h = camera.width, camera.height
    pixels = np.flatnonzero(problem.masks[view].numpy().reshape(-1))
    n = len(pixels) * spp
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, n)
    pixel_np = np.repeat(pixels, spp)
    pixel = mi.UInt32(pixel_np.astype(np.uint32))
    position = mi.Vector2f(mi.Float(pixel % w), mi.Float(pixel // w)) + sampler.next_2d()
    ray, _ = scene.sensors()[view].sample_ray(0.0, sampler.next_1d(), position / mi.Vector2f(w, h), sampler.next_2d())
    ctx = mi.BSDFContext()
    beta = mi.Spectrum(1.0)
    active = mi.Bool(True)
    prev_si = dr.zeros(mi.SurfaceInteraction3f, n)
    prev_pdf, prev_delta = mi.Float(1.0), mi.Bool(True)
    events: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def keep(mask, direction, weight) -> None:
        """Record the paths where `mask` holds: their pixel, the map's direction and the RGB weight of L there."""
        dr.eval(mask, direction, weight)
        m = np.asarray(mask, bool)
        if m.any():
            events.append((pixel_np[m], np.asarray(direction).T[m], np.asarray(weight).T[m]))

    for depth in range(renderer.settings.max_depth):
        si = scene.ray_intersect(ray, active)
        escaped = active & ~si.is_valid()
        ds = mi.DirectionSample3f(scene, si=si, ref=prev_si)
        mis = mis_weight(prev_pdf, scene.pdf_emitter_direction(prev_si, ds, ~prev_delta))
        keep(escaped, ray.d, beta * mis)
        active &= si.is_valid() & (depth + 1 < renderer.settings.max_depth)
        if depth + 1 >= renderer.settings.max_depth:
            break
        bsdf = si.bsdf(ray)
        active_em = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
        ds, _ = scene.sample_emitter_direction(si, sampler.next_2d(), False, active_em)
        active_em &= ds.pdf != 0.0
        active_em &= ~scene.ray_test(si.spawn_ray(ds.d), active_em)
        value, bsdf_pdf = bsdf.eval_pdf(ctx, si, si.to_local(ds.d), active_em)
        keep(active_em, ds.d, beta * value * mis_weight(ds.pdf, bsdf_pdf) / ds.pdf)
        sample, weight = bsdf.sample(ctx, si, sampler.next_1d(), sampler.next_2d(), active)
        ray = si.spawn_ray(si.to_world(sample.wo))
        beta *= weight
        prev_si = dr.detach(si, True)
        prev_pdf = sample.pdf
        prev_delta = mi.has_flag(sample.sampled_type, mi.BSDFFlags.Delta)
        active &= dr.max(beta) != 0
        dr.eval(ray, beta, prev_si, prev_pdf, prev_delta, active)
    return assemble(events, pixels, (h, w), height, spp)


def mis_weight(pdf_a, pdf_b):
    """The power heuristic, as Mitsuba's integrators weigh two sampling techniques."""
    import drjit as dr

    a2, b2 = dr.square(pdf_a), dr.square(pdf_b)
    return dr.detach(dr.select(pdf_a > 0, a2 / (a2 + b2), 0))


def assemble(events: list[tuple[np.ndarray, np.ndarray, np.ndarray]], pixels: np.ndarray, shape: tuple[int, int],
             height: int, spp: int) -> ViewTransport:
    """Sparse per-channel T from recorded (pixel, direction, RGB weight) events, averaged over `spp` paths."""
    row_of = np.full(shape[0] * shape[1], -1, np.int64)
    row_of[pixels] = np.arange(len(pixels))
    texels = 2 * height * height
    matrices = []
    if events:
        pixel = np.concatenate([e[0] for e in events])
        index, bilinear = texel_weights(np.concatenate([e[1] for e in events]), height)
        weight = np.concatenate([e[2] for e in events]) / spp
        rows = np.repeat(row_of[pixel], 4)
        for c in range(3):
            values = (bilinear * weight[:, c:c + 1]).reshape(-1)
            matrices.append(sp.csr_matrix((values, (rows, index.reshape(-1))), shape=(len(pixels), texels)))
    else:
        matrices = [sp.csr_matrix((len(pixels), texels)) for _ in range(3)]
    return ViewTransport(matrices, pixels, shape)


@dataclass
class Transport:
    """The data term's normal equations over the training views under fixed materials (module notes)."""

    gram: torch.Tensor
    """(3, N, N) per channel sum_v T_v^T W_v T_v, N = H x 2H texels (row-major)"""
    rhs: torch.Tensor
    """(3, N) per channel sum_v T_v^T W_v y_v"""
    constant: float
    """sum_v y_v^T W_v y_v: the loss of a black map"""
    height: int
    views: list[int]
    materials: MaterialTextures
    """the materials T was recorded with"""
    seconds: float
    """wall time of the recording"""
    entries: int
    """non-zeros of the views' sparse T (all channels), before the normal equations"""

    @property
    def nbytes(self) -> int:
        """Memory the data term keeps."""
        return self.gram.element_size() * self.gram.numel() + self.rhs.element_size() * self.rhs.numel()

    def data_loss(self, env: torch.Tensor) -> torch.Tensor:
        """Sum of the views' foreground mean squared errors under an (H, 2H, 3) map (differentiable)."""
        flat = env.reshape(-1, 3).T.to(self.gram.dtype)
        quadratic = (flat * torch.einsum("cij,cj->ci", self.gram, flat)).sum()
        return (quadratic - 2 * (self.rhs * flat).sum() + self.constant).clamp_min(0).to(env.dtype)

    def exposure(self, env: torch.Tensor) -> float:
        """The least-squares global scale c of the map against the views (c L fits best)."""
        flat = env.detach().reshape(-1, 3).T.to(self.gram.dtype)
        den = float((flat * torch.einsum("cij,cj->ci", self.gram, flat)).sum())
        num = float((self.rhs * flat).sum())
        return num / den if den > 0 and num > 0 else 1.0

    def stale(self, materials: MaterialTextures, tolerance: float) -> bool:
        """Whether the materials moved by more than `tolerance` (RMS over all texels) since the recording."""
        change = torch.cat([(a.detach() - b).reshape(-1) for (_, a), (_, b) in zip(materials.items(),
                                                                                    self.materials.items())])
        return float(change.square().mean().sqrt()) > tolerance


def record_transport(problem: InverseProblem, materials: MaterialTextures, env: torch.Tensor, spp: int, seed: int,
                     views: list[int] | None = None) -> Transport:
    """The normal equations of the data term over `views` (the training views) under `materials`, with
    next-event directions guided by `env` (module notes)."""
    start = time.perf_counter()
    views = list(problem.train_ids if views is None else views)
    height = problem.settings.env_height
    texels = 2 * height * height
    gram = np.zeros((3, texels, texels))
    rhs = np.zeros((3, texels))
    constant, entries = 0.0, 0
    guide = guide_map(env)
    for j, v in enumerate(views):
        t = record_view(problem, v, materials, guide, spp, seed * 1009 + j)
        weight = 1.0 / (3 * max(len(t.pixels), 1))
        y = problem.images[v].reshape(-1, 3).double().numpy()[t.pixels]
        for c, matrix in enumerate(t.matrices):
            gram[c] += weight * (matrix.T @ matrix).toarray()
            rhs[c] += weight * (matrix.T @ y[:, c])
            entries += matrix.nnz
        constant += weight * float(np.square(y).sum())
    return Transport(torch.from_numpy(gram), torch.from_numpy(rhs), constant, height, views, materials.detached(),
                     time.perf_counter() - start, entries)
