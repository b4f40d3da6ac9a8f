"""The light transport of the training views, recorded once: a data term without path tracing.

With the materials fixed, a rendered pixel is linear in the environment map's texels, I = T L
(per colour channel). `record_view` traces the paths of Mitsuba's `prb` integrator (camera ray,
then at every vertex next-event estimation towards the environment and a BSDF-sampled bounce,
both weighted by multiple importance sampling, up to `max_depth`), but where the integrator
multiplies a path's throughput by the map's radiance, it records (pixel, texel, throughput)
instead: the map's bilinear lookup (Mitsuba's own, see `texel_weights`) spreads each contribution
over its four texels. Next-event directions come from a fixed guide map (the current map with a
floor), not from the map T will be applied to, so T L is an unbiased render for every L.

A data term is a sum of squared foreground residuals, so `record_transport` keeps only its normal
equations, per channel: G = sum_v T_v^T T_v and b = sum_v T_v^T y_v. Then the sum of squares over
all training views under any map is L^T G L - 2 b^T L + k (milliseconds, memory (texels^2 x 3),
independent of the pixel count) and its gradient is 2 (G L - b). Each view's T at `spp` paths per pixel is noisy, so G carries the
variance of T L as a small ridge; `spp` sets it. T depends on the materials: `Transport.stale`
says when they have moved enough since the recording for a refresh.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from dpi.materials import MaterialTextures
from dpi.render import SEED_MODULUS
from dpi.solve.problem import InverseProblem

MAX_TRANSPORT_HEIGHT = 32
"""the largest map (rows) whose transport is recorded: its normal equations take (2 H^2)^2 x 3 floats (100 MB at
32 rows, 1.6 GB at 64) and its direct light one shadow ray per texel per camera sample"""
DIRECT_SPP = 4
"""camera samples per pixel of the stratified direct light (every cell of the map gets a shadow ray from each)"""
BRIGHT_SHARE = 0.5
"""the brightest texels that hold this share of the guide map's energy get extra direct-light draws ..."""
BRIGHT_SPP = 16
"""... this many more per pixel (a sun's column of T is most of the image: its noise is most of T's)"""
FOOTPRINT = 64
"""points of a pixel's area the direct light is seen through (each texel through one of them)"""
CHUNK_LANES = 1 << 20
"""lanes of one Dr.Jit launch of the direct light (camera samples x cells)"""
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
    """T of one view: a dense (3, foreground pixels, texels) array, and which pixels its rows are."""

    matrix: np.ndarray
    pixels: np.ndarray
    """flat indices (row-major in the (h, w) image) of the rows"""
    shape: tuple[int, int]
    column_variance: np.ndarray
    """(3, texels): the sum over the rows of the estimated variance of each entry (its direct light's): the part of
    E[T^T T] that T's noise adds to its diagonal"""

    def image(self, env: np.ndarray) -> np.ndarray:
        """The view's (h, w, 3) image under an (H, 2H, 3) map: T L on the foreground, 0 elsewhere."""
        out = np.zeros((self.shape[0] * self.shape[1], 3))
        out[self.pixels] = np.einsum("cpn,nc->pc", self.matrix, env.reshape(-1, 3))
        return out.reshape(*self.shape, 3)


def guide_map(env: torch.Tensor) -> np.ndarray:
    """The next-event guide: the map plus GUIDE_FLOOR times its mean (positive everywhere)."""
    env = env.detach().double().clamp_min(0).numpy()
    return (env + GUIDE_FLOOR * max(float(env.mean()), 1e-12)).astype(np.float32)


class Accumulator:
    """Adds (pixel, direction, RGB weight) contributions into a view's dense T through the map's lookup."""

    def __init__(self, pixels: np.ndarray, image_size: int, height: int):
        self.row_of = np.full(image_size, -1, np.int64)
        self.row_of[pixels] = np.arange(len(pixels))
        self.height, self.texels = height, 2 * height * height
        self.matrix = np.zeros((3, len(pixels), self.texels))

    def add(self, pixel: np.ndarray, direction: np.ndarray, weight: np.ndarray) -> None:
        """T[c, pixel, texel] += weight_c x bilinear(texel; direction) for every contribution."""
        if len(pixel) == 0:
            return
        index, bilinear = texel_weights(direction, self.height)
        flat = (self.row_of[pixel][:, None] * self.texels + index).reshape(-1)
        size = self.matrix[0].size
        for c in range(3):
            self.matrix[c] += np.bincount(flat, (bilinear * weight[:, c:c + 1]).reshape(-1),
                                          minlength=size).reshape(self.matrix[c].shape)


def texel_density(direction_y, height: int):
    """Solid-angle density, times the number of texels, of `record_direct`'s directions (one per texel, each
    drawn in proportion to its bilinear tent): sum_j tent_j / |tent_j| over 2 pi^2 sin(theta). Interior tents
    all have the area du dv and sum to 1; the first and last rows' are halved at the poles."""
    import drjit as dr

    du, dv = 1.0 / (2 * height), 1.0 / (height - 1)
    v = dr.safe_acos(direction_y) / np.pi
    edge = dr.maximum(1 - v / dv, 0) + dr.maximum(1 - (1 - v) / dv, 0)
    return (1 + edge) / (du * dv * 2 * np.pi ** 2 * dr.maximum(dr.safe_sqrt(1 - dr.square(direction_y)), 1e-4))


def camera_rays(mi, sensor, pixel: np.ndarray, jitter: np.ndarray, size: tuple[int, int]):
    """Primary rays through `pixel` (flat indices) at sub-pixel offsets `jitter` (n, 2) of an (h, w) image."""
    h, w = size
    position = mi.Vector2f((pixel % w + jitter[:, 0]) / w, (pixel // w + jitter[:, 1]) / h)
    ray, _ = sensor.sample_ray(0.0, 0.5, position, mi.Point2f(0.5, 0.5))
    return ray


def tent_inverse(xi):
    """The inverse CDF of the tent 1 - |x| on [-1, 1]: a uniform xi in [0, 1) to a tent-distributed x."""
    import drjit as dr

    return dr.select(xi < 0.5, dr.sqrt(2 * xi) - 1, 1 - dr.sqrt(2 * (1 - xi)))


def record_direct(mi, scene, sensor, pixels: np.ndarray, size: tuple[int, int], height: int, spp: int,
                  seed: int, rng: np.random.Generator, cells: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Light arriving straight from the map at the first surface point, texel by texel: for every texel one
    direction drawn in proportion to its bilinear tent in (u, v) (Mitsuba's lookup, `texel_weights`; so a sun's
    texel is never missed and gets its exact share), shadow-tested, weighted against BSDF sampling by the
    balance heuristic (`record_paths` takes the rest); `spp` camera samples per pixel. The sample's weight is
    f cos / (its density + the BSDF's), times the tent's area over its density in (u, v), 2 pi^2 sin(theta) |tent|
    (the first and last rows' tents are halves at the poles: their draws fold back). Returns the (3, pixels,
    texels) estimate, zero outside `cells` (default all), and its variance estimated from the draws' spread."""
    import drjit as dr

    width, texels, ctx = 2 * height, 2 * height * height, mi.BSDFContext()
    du, dv = 1.0 / width, 1.0 / (height - 1)
    samples = len(pixels) * spp
    row = mi.UInt32(np.repeat(np.arange(len(pixels)), spp).astype(np.uint32))
    pixel = mi.UInt32(np.repeat(pixels, spp).astype(np.uint32))
    jitter = ((np.arange(FOOTPRINT)[None, :, None] + rng.random((len(pixels), FOOTPRINT, 2)))
              / FOOTPRINT).astype(np.float32)  # stratified in x and y (as Latin hypercube rows), per pixel
    jitter[..., 1] = np.take_along_axis(jitter[..., 1], rng.permuted(np.tile(np.arange(FOOTPRINT), (len(pixels), 1)),
                                                                      axis=1), axis=1)
    jx, jy = mi.Float(jitter[..., 0].reshape(-1)), mi.Float(jitter[..., 1].reshape(-1))
    size_flat = len(pixels) * texels
    sums = np.zeros((6, size_flat))  # per channel: the draws' sum, their sum of squares
    cells = np.arange(texels) if cells is None else np.asarray(cells)
    cell_list = mi.UInt32(cells.astype(np.uint32))
    chunk = max(1, min(len(cells), CHUNK_LANES // max(samples, 1)))
    sampler = mi.load_dict({"type": "independent"})
    side = max(1, int(spp ** 0.5))
    for first in range(0, len(cells), chunk):
        count = min(chunk, len(cells) - first)
        lane = dr.arange(mi.UInt32, samples * count)
        h = lane // count
        cell = dr.gather(mi.UInt32, cell_list, first + lane % count)
        p = dr.gather(mi.UInt32, pixel, h)
        # each texel sees the pixel through another of its FOOTPRINT points: an image under a whole map averages
        # the pixel's area over all of them (a render with FOOTPRINT samples), at one ray per texel
        footprint = dr.gather(mi.UInt32, row, h) * FOOTPRINT + (cell * 37 + (h % spp) * 11) % FOOTPRINT
        position = mi.Point2f((mi.Float(p % size[1]) + dr.gather(mi.Float, jx, footprint)) / size[1],
                              (mi.Float(p // size[1]) + dr.gather(mi.Float, jy, footprint)) / size[0])
        ray, _ = sensor.sample_ray(0.0, 0.5, position, mi.Point2f(0.5, 0.5))
        sampler.seed(int(seed + first) % SEED_MODULUS, samples * count)
        stratum = (h % spp) % (side * side)  # a pixel's camera samples split each tent into side x side strata
        cell_row, cell_col = cell // width, cell % width
        xi = (mi.Point2f(mi.Float(stratum % side), mi.Float(stratum // side)) + sampler.next_2d()) / side
        u = (mi.Float(cell_col) + 0.5 + tent_inverse(xi.x)) * du
        u -= dr.floor(u)
        v = dr.abs((mi.Float(cell_row) + tent_inverse(xi.y)) * dv)
        v = dr.select(v > 1, 2 - v, v)
        theta, phi = dr.pi * v, 2 * dr.pi * u
        d = mi.Vector3f(dr.sin(phi) * dr.sin(theta), dr.cos(theta), -dr.cos(phi) * dr.sin(theta))
        area = du * dv * dr.select((cell_row == 0) | (cell_row == height - 1), 0.5, 1.0)
        si = scene.ray_intersect(ray)
        bsdf = si.bsdf(ray)
        hit = si.is_valid() & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
        value, bsdf_pdf = bsdf.eval_pdf(ctx, si, si.to_local(d), hit)
        hit &= ~scene.ray_test(si.spawn_ray(d), hit)
        density = texel_density(d.y, height)
        weight = value * (density / (density + bsdf_pdf) * area * 2 * dr.pi ** 2 * dr.sin(theta) / spp)
        index = dr.gather(mi.UInt32, row, h) * texels + cell
        dr.eval(weight, index, hit)
        # summed in NumPy, in a fixed order: Dr.Jit's parallel atomic adds sum in whatever order its threads
        # run, and a seeded sample must come out the same twice
        kept = np.asarray(hit)
        flat, draws = np.asarray(index)[kept], np.asarray(weight, np.float64)[:, kept]
        for c in range(3):
            sums[c] += np.bincount(flat, draws[c], minlength=size_flat)
            sums[3 + c] += np.bincount(flat, np.square(draws[c]), minlength=size_flat)
    shape = (3, len(pixels), texels)
    mean, squares = sums[:3].reshape(shape), sums[3:].reshape(shape)
    variance = (spp * squares - mean ** 2) / (spp - 1) if spp > 1 else mean ** 2  # of the mean of spp draws
    return mean, variance.clip(min=0)


def bright_texels(guide: np.ndarray, share: float) -> np.ndarray:
    """The fewest texels that carry `share` of the guide map's energy (luminance x solid angle), if they are
    at most an eighth of the map (a sun, a window); none for a map whose light is spread out."""
    from dpi.envmap import texel_solid_angles
    from dpi.images import luminance

    energy = (luminance(guide) * texel_solid_angles(guide.shape[0])).reshape(-1)
    order = np.argsort(energy)[::-1]
    count = int(np.searchsorted(np.cumsum(energy[order]) / max(energy.sum(), 1e-30), share)) + 1
    return np.sort(order[:count]) if count <= energy.size // 8 else np.zeros(0, np.int64)


def record_paths(mi, scene, sensor, pixels: np.ndarray, size: tuple[int, int], height: int, spp: int,
                 max_depth: int, seed: int, rng: np.random.Generator, accumulator: Accumulator) -> None:
    """Everything but `record_direct`'s part, along prb's paths (`spp` per pixel): the map seen by the camera,
    BSDF-sampled rays that escape (after the first surface point weighted against the stratified cells, after
    later ones against next-event estimation), and next-event estimation from the second point on."""
    import drjit as dr

    pixel = np.repeat(pixels, spp)
    n = len(pixel)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(int(seed) % SEED_MODULUS, n)
    ray = camera_rays(mi, sensor, pixel, rng.random((n, 2)), size)
    ctx = mi.BSDFContext()
    beta = mi.Spectrum(1.0 / spp)
    active = mi.Bool(True)
    prev_si = dr.zeros(mi.SurfaceInteraction3f, n)
    prev_pdf, prev_delta = mi.Float(1.0), mi.Bool(True)

    def keep(mask, direction, weight) -> None:
        dr.eval(mask, direction, weight)
        m = np.asarray(mask, bool)
        accumulator.add(pixel[m], np.asarray(direction).T[m], np.asarray(weight).T[m])

    for depth in range(max_depth):
        si = scene.ray_intersect(ray, active)
        escaped = active & ~si.is_valid()
        if depth == 1:  # against record_direct's texel-by-texel draws
            mis = dr.select(prev_delta, 1.0, prev_pdf / (prev_pdf + texel_density(ray.d.y, height)))
        else:
            ds = mi.DirectionSample3f(scene, si=si, ref=prev_si)
            mis = mis_weight(prev_pdf, scene.pdf_emitter_direction(prev_si, ds, ~prev_delta))
        keep(escaped, ray.d, beta * mis)
        active &= si.is_valid() & (depth + 1 < max_depth)
        if depth + 1 >= max_depth:
            break
        bsdf = si.bsdf(ray)
        if depth >= 1:
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


def record_view(problem: InverseProblem, view: int, materials: MaterialTextures, guide: np.ndarray, spp: int,
                seed: int, direct_spp: int | None = None) -> ViewTransport:
    """T of one view's foreground pixels (module notes): `direct_spp` camera samples per pixel for the light
    arriving straight from the map, `spp` paths per pixel for the rest; seeded."""
    renderer = problem.renderer
    renderer.set_scene(torch.from_numpy(guide), materials.albedo, materials.roughness, materials.metallic)
    mi, scene, height = renderer.mi, renderer.scene, renderer.env_height
    camera = renderer.cameras[view]
    size = (camera.height, camera.width)
    pixels = np.flatnonzero(problem.masks[view].numpy().reshape(-1))
    sensor = scene.sensors()[view]
    rng = np.random.default_rng(seed)
    accumulator = Accumulator(pixels, size[0] * size[1], height)
    direct_spp = direct_spp or DIRECT_SPP
    direct, variance = record_direct(mi, scene, sensor, pixels, size, height, direct_spp, seed * 7 + 1, rng)
    bright = bright_texels(guide, BRIGHT_SHARE)
    if len(bright):  # the texels that carry most of the light get BRIGHT_SPP draws more
        extra, extra_variance = record_direct(mi, scene, sensor, pixels, size, height, BRIGHT_SPP, seed * 7 + 2, rng,
                                              bright)
        a, b = direct_spp / (direct_spp + BRIGHT_SPP), BRIGHT_SPP / (direct_spp + BRIGHT_SPP)
        direct[:, :, bright] = a * direct[:, :, bright] + b * extra[:, :, bright]
        variance[:, :, bright] = a ** 2 * variance[:, :, bright] + b ** 2 * extra_variance[:, :, bright]
    accumulator.matrix += direct
    record_paths(mi, scene, sensor, pixels, size, height, spp, renderer.settings.max_depth, seed, rng, accumulator)
    return ViewTransport(accumulator.matrix, pixels, size, variance.sum(axis=1))


def mis_weight(pdf_a, pdf_b):
    """The power heuristic, as Mitsuba's integrators weigh two sampling techniques."""
    import drjit as dr

    a2, b2 = dr.square(pdf_a), dr.square(pdf_b)
    return dr.detach(dr.select(pdf_a > 0, a2 / (a2 + b2), 0))


@dataclass
class Transport:
    """The data term's normal equations over the training views under fixed materials (module notes)."""

    gram: torch.Tensor
    """(3, N, N) per channel sum_v T_v^T T_v, N = H x 2H texels (row-major)"""
    rhs: torch.Tensor
    """(3, N) per channel sum_v T_v^T y_v"""
    constant: float
    """sum_v y_v^T y_v: the sum of squares of a black map"""
    pixels: int
    """foreground pixels of the views (each with 3 channels)"""
    height: int
    views: list[int]
    materials: MaterialTextures
    """the materials T was recorded with"""
    seconds: float
    """wall time of the recording"""
    entries: int
    """non-zeros of the views' T (all channels), before the normal equations"""
    column_variance: torch.Tensor
    """(3, N) the recording's noise: per texel, the summed variance of its entries (`ViewTransport`)"""

    @property
    def nbytes(self) -> int:
        """Memory the data term keeps."""
        return self.gram.element_size() * self.gram.numel() + self.rhs.element_size() * self.rhs.numel()

    def sum_squares(self, env: torch.Tensor, rhs: torch.Tensor | None = None) -> torch.Tensor:
        """Sum of squared foreground residuals of the views under an (H, 2H, 3) map (differentiable, float64);
        `rhs` replaces b (a perturbed data term)."""
        flat = env.reshape(-1, 3).T.to(self.gram.dtype)
        quadratic = (flat * torch.einsum("cij,cj->ci", self.gram, flat)).sum()
        return quadratic - 2 * ((self.rhs if rhs is None else rhs) * flat).sum() + self.constant

    def mean_squares(self, env: torch.Tensor) -> torch.Tensor:
        """Mean squared foreground residual per pixel and channel over the views (differentiable)."""
        return (self.sum_squares(env) / (3 * self.pixels)).clamp_min(0).to(env.dtype)

    def exposure(self, env: torch.Tensor) -> float:
        """The least-squares global scale c of the map against the views (c L fits best)."""
        flat = env.detach().reshape(-1, 3).T.to(self.gram.dtype)
        den = float((flat * torch.einsum("cij,cj->ci", self.gram, flat)).sum())
        num = float((self.rhs * flat).sum())
        return num / den if den > 0 and num > 0 else 1.0

    def noise(self, env: torch.Tensor) -> float:
        """The recording's own noise in an image under an (H, 2H, 3) map: the variance of T L per pixel and channel
        (its direct light's, from the spread of its draws), which a fit to this T cannot tell from the data."""
        flat = env.detach().reshape(-1, 3).T.to(self.column_variance.dtype)
        return float((self.column_variance * flat.square()).sum()) / (3 * self.pixels)

    def stale(self, materials: MaterialTextures, tolerance: float) -> bool:
        """Whether the materials moved by more than `tolerance` (RMS over all texels) since the recording."""
        change = torch.cat([(a.detach() - b).reshape(-1) for (_, a), (_, b) in zip(materials.items(),
                                                                                    self.materials.items())])
        return float(change.square().mean().sqrt()) > tolerance


def without_noise(gram: np.ndarray, column_variance: np.ndarray) -> np.ndarray:
    """T^T T less the recording's noise on its diagonal (E[T^T T] = T-bar^T T-bar + that noise). The estimated
    noise is itself noisy and can leave a direction of slightly negative curvature: the diagonal is then raised
    by the smallest eigenvalue (found by Lanczos iterations, cheap at 2048 texels unlike a full
    eigendecomposition), so the data term stays convex. Lanczos starts from a fixed vector: ARPACK's own random
    start changes from call to call, and a seeded sample must come out the same twice."""
    from scipy.sparse.linalg import eigsh

    index = np.arange(gram.shape[-1])
    start = np.ones(gram.shape[-1])
    for c in range(gram.shape[0]):
        gram[c, index, index] -= column_variance[c]
        lowest = float(eigsh(gram[c], k=1, which="SA", return_eigenvectors=False, tol=1e-6, v0=start)[0])
        if lowest < 0:
            gram[c, index, index] -= lowest
    return gram


def record_transport(problem: InverseProblem, materials: MaterialTextures, env: torch.Tensor, spp: int, seed: int,
                     views: list[int] | None = None, direct_spp: int | None = None) -> Transport:
    """The normal equations of the data term over `views` (the training views) under `materials`, with
    next-event directions guided by `env` (module notes)."""
    start = time.perf_counter()
    views = list(problem.train_ids if views is None else views)
    height = problem.settings.env_height
    texels = 2 * height * height
    gram = np.zeros((3, texels, texels))
    rhs = np.zeros((3, texels))
    constant, entries, pixels = 0.0, 0, 0
    column_variance = np.zeros((3, texels))
    guide = guide_map(env)
    for j, v in enumerate(views):
        t = record_view(problem, v, materials, guide, spp, seed * 1009 + j, direct_spp)
        y = problem.images[v].reshape(-1, 3).double().numpy()[t.pixels]
        gram += t.matrix.transpose(0, 2, 1) @ t.matrix
        column_variance += t.column_variance
        rhs += np.einsum("cpi,pc->ci", t.matrix, y)
        entries += int(np.count_nonzero(t.matrix))
        constant += float(np.square(y).sum())
        pixels += len(t.pixels)
    gram = without_noise(gram, column_variance)
    return Transport(torch.from_numpy(gram), torch.from_numpy(rhs), constant, pixels, height, views,
                     materials.detached(), time.perf_counter() - start, entries, torch.from_numpy(column_variance))
