"""The light transport of the training views, recorded once: a data term without path tracing.

Mitsuba's principled BSDF is affine in its base colour a: f(a) = a (f(1) - f(0)) + f(0), and its
sampling does not depend on a. So with the roughness and metallic fixed, a pixel's value is
  I_p = a_p (A_p L) + B_p L          (per colour channel)
with L the environment map's texels, a_p the albedo the pixel sees (the mean bilinear lookup of the
texture over the pixel's footprint, `albedo_lookup`), A_p the transport of the light that the first
surface point's base colour scales and B_p the rest (a dielectric's specular, light seen directly).
Light that bounces more than once is recorded under the albedo of the recording at its later
surface points. An image under any map and albedo is then two matrix products (milliseconds), and
so are its gradients: samplers draw the map and the albedo from it instead of path tracing.

`record_view` traces the paths of Mitsuba's `prb` integrator (camera ray, then at every vertex
next-event estimation towards the environment and a BSDF-sampled bounce, weighted by multiple
importance sampling), but where the integrator multiplies a path's throughput by the map's
radiance it records (pixel, texel, throughput) instead: the map's bilinear lookup (Mitsuba's own,
`texel_weights`) spreads each contribution over its four texels. The light arriving straight from
the map at the first surface point is recorded texel by texel (every texel gets a shadow ray from
each camera sample, so a sun is never missed); for a glossy object only the bright texels are, and its BSDF's
samples, which find a narrow lobe well, take the other texels' columns whole (`record_view`'s `every_texel`).
Next-event directions come from a guide map (the current map with a floor), not from the map T is applied to, so
T L is an unbiased render for every L.

Every recording is two independent halves (each from half of the samples). A data term is a sum of
squares, and the square of one noisy recording overestimates it by the recording's variance, most
at the brightest texels (a sun): the product of the two halves' residuals does not (E[T1^T T2] = T^T T).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from dpi.render.renderer import SEED_MODULUS, texture_plugin
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem
from dpi.solve.transport.operator import AlbedoLookup, LightTransport, resize_map
from dpi.solve.transport.settings import HALVES, ROUGH_TRANSPORT_HEIGHT, TransportConfig, transport_height

BRIGHT_SHARE = 0.5
"""the brightest texels that hold this share of the guide map's energy get extra direct-light draws ..."""


BRIGHT_SPP = 16
"""... this many more per pixel (a sun's column of T is most of the image: its noise is most of T's)"""


FOOTPRINT = 64
"""points of a pixel's area the direct light and the albedo lookup are seen through (each texel through one)"""


CHUNK_LANES = 1 << 20
"""lanes of one Dr.Jit launch of the direct light (camera samples x cells)"""


GUIDE_FLOOR = 0.25
"""the guide map for next-event directions is the map plus this share of its mean: every texel keeps a
chance to be sampled, so T stays unbiased and useful for maps brighter elsewhere"""


def texel_weights(directions: np.ndarray, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel indices (n, 4) into an (H, 2H) map and bilinear weights (n, 4) of Mitsuba's envmap lookup at
    world directions (n, 3): columns at u = atan2(x, -z) / 2pi are texel centres, rows at v = acos(y) / pi
    span the poles (row r at v = r / (H - 1)), azimuth wraps (dpi.light.envmap documents the map's layout)."""
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


def texture_weights(uv: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel indices (n, 4) into a (size, size) texture and bilinear weights (n, 4) of Mitsuba's bitmap lookup
    (filter bilinear, wrap clamp) at surface coordinates uv (n, 2): texel centres at (i + 0.5) / size, row
    index from uv's second coordinate."""
    x = np.asarray(uv, np.float64) * size - 0.5
    base = np.floor(x)
    f = x - base
    lo = np.clip(base, 0, size - 1).astype(np.int64)
    hi = np.clip(base + 1, 0, size - 1).astype(np.int64)
    index = np.stack([lo[:, 1] * size + lo[:, 0], lo[:, 1] * size + hi[:, 0],
                      hi[:, 1] * size + lo[:, 0], hi[:, 1] * size + hi[:, 0]], axis=1)
    weight = np.stack([(1 - f[:, 0]) * (1 - f[:, 1]), f[:, 0] * (1 - f[:, 1]),
                       (1 - f[:, 0]) * f[:, 1], f[:, 0] * f[:, 1]], axis=1)
    return index, weight


def guide_map(env: torch.Tensor) -> np.ndarray:
    """The next-event guide: the map plus GUIDE_FLOOR times its mean (positive everywhere)."""
    env = env.detach().double().clamp_min(0).numpy()
    return (env + GUIDE_FLOOR * max(float(env.mean()), 1e-12)).astype(np.float32)


class Bins:
    """Contributions to a few entries of a large array, summed by entry in NumPy in a fixed order (Dr.Jit's
    parallel atomic adds sum in whatever order its threads run, and a seeded sample must come out the same
    twice): the entries are sorted once, then each weight vector costs one small bincount."""

    def __init__(self, flat: np.ndarray):
        self.entries, self.inverse = np.unique(flat, return_inverse=True)

    def add(self, target: np.ndarray, weights: np.ndarray) -> None:
        """target[flat] += weights (target: a flat view)."""
        target[self.entries] += np.bincount(self.inverse, weights, minlength=len(self.entries))


class Accumulator:
    """Adds (pixel, direction, half, weights of A and B) contributions into a view's dense transports through the
    map's lookup: `matrix` (2 (slope, offset), HALVES, 3, pixels, texels)."""

    def __init__(self, count: int, height: int, drawn: np.ndarray | None = None):
        self.height, self.texels = height, 2 * height * height
        self.matrix = np.zeros((2, HALVES, 3, count, self.texels), np.float32)
        self.drawn = drawn
        """the texels `record_direct` draws (a bool per texel); None: every texel"""

    def add(self, row: np.ndarray, half: np.ndarray, direction: np.ndarray, slope: np.ndarray,
            offset: np.ndarray, drawn_factor: np.ndarray | None = None) -> None:
        """T[half, c, row, texel] += weight_c x bilinear(texel; direction) for every contribution (weights
        (n, 3)); `drawn_factor` (one per contribution) applies to the drawn texels' columns only: a BSDF sample
        shares a column with `record_direct`'s draws of that texel alone."""
        if len(row) == 0:
            return
        index, bilinear = texel_weights(direction, self.height)
        if drawn_factor is not None:
            bilinear = np.where(self.drawn[index], drawn_factor[:, None] * bilinear, bilinear)
        rows = self.matrix.shape[3]
        bins = Bins(((half[:, None] * 3 * rows + row[:, None]) * self.texels + index).reshape(-1))
        for part, weight in enumerate((slope, offset)):
            block = self.matrix[part].reshape(-1)
            for c in range(3):  # channel c of half h starts at (h * 3 + c) * rows * texels of the block
                bins.add(block[c * rows * self.texels:], (bilinear * weight[:, c:c + 1]).reshape(-1))


def texel_density(direction_y, height: int):
    """Solid-angle density, times the number of texels, of `record_direct`'s directions (one per texel, each
    drawn in proportion to its bilinear tent): sum_j tent_j / |tent_j| over 2 pi^2 sin(theta). Interior tents
    all have the area du dv and sum to 1; the first and last rows' are halved at the poles."""
    import drjit as dr

    du, dv = 1.0 / (2 * height), 1.0 / (height - 1)
    v = dr.safe_acos(direction_y) / np.pi
    edge = dr.maximum(1 - v / dv, 0) + dr.maximum(1 - (1 - v) / dv, 0)
    return (1 + edge) / (du * dv * 2 * np.pi ** 2 * dr.maximum(dr.safe_sqrt(1 - dr.square(direction_y)), 1e-4))


def tent_inverse(xi):
    """The inverse CDF of the tent 1 - |x| on [-1, 1]: a uniform xi in [0, 1) to a tent-distributed x."""
    import drjit as dr

    return dr.select(xi < 0.5, dr.sqrt(2 * xi) - 1, 1 - dr.sqrt(2 * (1 - xi)))


@dataclass
class ViewSetup:
    """What the recorders of one view share: Mitsuba's scene and sensor, the pixels (flat indices into the
    (h, w) image) and their footprints, and the BSDFs of base colour 0 and 1 (the rest as recorded)."""

    mi: object
    scene: object
    sensor: object
    pixels: np.ndarray
    size: tuple[int, int]
    height: int
    footprint: tuple[np.ndarray, np.ndarray]
    """(pixels x FOOTPRINT) sub-pixel offsets in x and y, stratified"""
    bsdfs: tuple[object, object]
    """the principled BSDF of the materials' roughness and metallic at base colour 0 and at 1"""

    def footprint_position(self, row, point):
        """Film position of footprint point `point` of pixel row `row` (Dr.Jit arrays)."""
        import drjit as dr

        mi, h, w = self.mi, *self.size
        pixel = dr.gather(mi.UInt32, mi.UInt32(self.pixels.astype(np.uint32)), row)
        index = row * FOOTPRINT + point
        return mi.Point2f((mi.Float(pixel % w) + dr.gather(mi.Float, mi.Float(self.footprint[0]), index)) / w,
                          (mi.Float(pixel // w) + dr.gather(mi.Float, mi.Float(self.footprint[1]), index)) / h)

    def first_bounce(self, si, direction, active):
        """(f(1) - f(0), f(0), pdf) of the principled BSDF at `si` towards world `direction` (cosine included; the
        sampling density does not depend on the base colour)."""
        ctx, wo = self.mi.BSDFContext(), si.to_local(direction)
        dark, bright = self.bsdfs
        offset, pdf = dark.eval_pdf(ctx, si, wo, active)
        return bright.eval(ctx, si, wo, active) - offset, offset, pdf


def view_setup(problem: InverseProblem, view: int, pixels: np.ndarray, materials: MaterialTextures,
               guide: np.ndarray, height: int, rng: np.random.Generator) -> ViewSetup:
    """The scene under the guide map and `materials` (their roughness samples the paths), and what the recorders
    of `view` share; `height`: the rows of the maps T takes."""
    renderer = problem.renderer
    renderer.set_scene(torch.from_numpy(guide), materials.albedo, materials.roughness, materials.metallic)
    mi = renderer.mi
    camera = renderer.cameras[view]
    metallic = texture_plugin(materials.metallic.detach().float().numpy())
    roughness = texture_plugin(materials.roughness.detach().float().numpy())
    bsdfs = tuple(mi.load_dict({"type": "principled", "base_color": {"type": "rgb", "value": value},
                                "roughness": roughness, "metallic": metallic}) for value in (0.0, 1.0))
    jitter = ((np.arange(FOOTPRINT)[None, :, None] + rng.random((len(pixels), FOOTPRINT, 2)))
              / FOOTPRINT).astype(np.float32)  # stratified in x and y (as Latin hypercube rows), per pixel
    jitter[..., 1] = np.take_along_axis(jitter[..., 1], rng.permuted(np.tile(np.arange(FOOTPRINT), (len(pixels), 1)),
                                                                      axis=1), axis=1)
    return ViewSetup(mi, renderer.scene, renderer.scene.sensors()[view], pixels, (camera.height, camera.width),
                     height, (jitter[..., 0].reshape(-1), jitter[..., 1].reshape(-1)), bsdfs)


def albedo_lookup(setup: ViewSetup, texture_size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each pixel's mean bilinear weights of the albedo texture over the FOOTPRINT points that hit the object:
    COO (rows, texel indices, weights); a pixel that misses the object everywhere has none."""
    import drjit as dr

    mi, count = setup.mi, len(setup.pixels) * FOOTPRINT
    lane = dr.arange(mi.UInt32, count)
    ray, _ = setup.sensor.sample_ray(0.0, 0.5, setup.footprint_position(lane // FOOTPRINT, lane % FOOTPRINT),
                                     mi.Point2f(0.5, 0.5))
    si = setup.scene.ray_intersect(ray)
    dr.eval(si.uv, si.is_valid())
    hit = np.asarray(si.is_valid(), bool)
    uv = np.asarray(si.uv).T[hit]
    rows = np.repeat(np.arange(len(setup.pixels)), FOOTPRINT)[hit]
    index, weight = texture_weights(uv, texture_size)
    hits = np.bincount(rows, minlength=len(setup.pixels))
    pairs = np.repeat(rows, 4) * texture_size ** 2 + index.reshape(-1)  # (pixel, texel), each pair summed once
    unique, inverse = np.unique(pairs, return_inverse=True)
    total = np.bincount(inverse, (weight / hits[rows, None]).reshape(-1))
    return unique // texture_size ** 2, unique % texture_size ** 2, total


def record_direct(setup: ViewSetup, spp: int, seed: int, cells: np.ndarray) -> np.ndarray:
    """Light arriving straight from the map at the first surface point, texel by texel: for every texel one
    direction drawn in proportion to its bilinear tent in (u, v) (Mitsuba's lookup, `texel_weights`; so a sun's
    texel is never missed and gets its exact share), shadow-tested, weighted against the BSDF's sampling
    by the balance heuristic (`record_paths` takes the rest); `spp` camera samples per pixel, alternately in the
    two halves. The sample's weight is f cos / (its density + the BSDF's), times the tent's area over its density
    in (u, v), 2 pi^2 sin(theta) |tent| (the first and last rows' tents are halves at the poles: their draws fold
    back). Returns the columns of `cells`: (2 (slope, offset), HALVES, 3, pixels, cells). A launch draws
    one camera sample of each half for every (pixel, cell) of a chunk of cells, so its lanes fill a dense block:
    summed by plain array additions, in a fixed order (Dr.Jit's parallel atomic adds sum in whatever order its
    threads run, and a seeded sample must come out the same twice)."""
    import drjit as dr

    mi, height = setup.mi, setup.height
    width = 2 * height
    du, dv = 1.0 / width, 1.0 / (height - 1)
    rows = len(setup.pixels)
    cell_list = mi.UInt32(np.asarray(cells).astype(np.uint32))
    out = np.zeros((2, HALVES, 3, rows, len(cells)), np.float32)
    chunk = max(1, min(len(cells), CHUNK_LANES // max(HALVES * rows, 1)))
    sampler = mi.load_dict({"type": "independent"})
    per_half = spp // HALVES
    side = max(1, int(per_half ** 0.5))
    for first in range(0, len(cells), chunk):
        count = min(chunk, len(cells) - first)
        for s in range(per_half):  # lanes: (half, pixel row, cell); camera sample j = s HALVES + half
            lane = dr.arange(mi.UInt32, HALVES * rows * count)
            cell = dr.gather(mi.UInt32, cell_list, first + lane % count)
            row = (lane // count) % rows
            j = (lane // (count * rows)) + s * HALVES
            # each texel sees the pixel through another of its FOOTPRINT points: an image under a whole map
            # averages the pixel's area over all of them (a render with FOOTPRINT samples), at one ray per texel
            ray, _ = setup.sensor.sample_ray(0.0, 0.5, setup.footprint_position(row, (cell * 37 + j * 11) % FOOTPRINT),
                                             mi.Point2f(0.5, 0.5))
            sampler.seed(int(seed + first * spp + s) % SEED_MODULUS, HALVES * rows * count)
            stratum = s % (side * side)  # each half's camera samples split each tent into side x side strata
            cell_row, cell_col = cell // width, cell % width
            xi = (mi.Point2f(mi.Float(stratum % side), mi.Float(stratum // side)) + sampler.next_2d()) / side
            u = (mi.Float(cell_col) + 0.5 + tent_inverse(xi.x)) * du
            u -= dr.floor(u)
            v = dr.abs((mi.Float(cell_row) + tent_inverse(xi.y)) * dv)
            v = dr.select(v > 1, 2 - v, v)
            theta, phi = dr.pi * v, 2 * dr.pi * u
            d = mi.Vector3f(dr.sin(phi) * dr.sin(theta), dr.cos(theta), -dr.cos(phi) * dr.sin(theta))
            area = du * dv * dr.select((cell_row == 0) | (cell_row == height - 1), 0.5, 1.0)
            si = setup.scene.ray_intersect(ray)
            hit = si.is_valid() & mi.has_flag(si.bsdf(ray).flags(), mi.BSDFFlags.Smooth)
            hit &= ~setup.scene.ray_test(si.spawn_ray(d), hit)
            density = texel_density(d.y, height)
            scale = dr.select(hit, area * 2 * dr.pi ** 2 * dr.sin(theta) / per_half, 0.0)
            slope, offset, bsdf_pdf = setup.first_bounce(si, d, hit)
            weight = scale * density / (density + bsdf_pdf)
            pair = (slope * weight, offset * weight)
            dr.eval(*pair)
            for part, value in enumerate(pair):
                out[part, ..., first:first + count] += np.asarray(value).reshape(3, HALVES, rows, count
                                                                                 ).transpose(1, 0, 2, 3)
    return out


def bright_texels(guide: np.ndarray, share: float) -> np.ndarray:
    """The fewest texels that carry `share` of the guide map's energy (luminance x solid angle), if they are
    at most an eighth of the map (a sun, a window); none for a map whose light is spread out."""
    from dpi.io.images import luminance
    from dpi.light.envmap import texel_solid_angles

    energy = (luminance(guide) * texel_solid_angles(guide.shape[0])).reshape(-1)
    order = np.argsort(energy)[::-1]
    count = int(np.searchsorted(np.cumsum(energy[order]) / max(energy.sum(), 1e-30), share)) + 1
    return np.sort(order[:count]) if count <= energy.size // 8 else np.zeros(0, np.int64)


def record_paths(setup: ViewSetup, accumulator: Accumulator, spp: int, max_depth: int, seed: int,
                 rng: np.random.Generator) -> None:
    """Everything but `record_direct`'s part, along prb's paths (`spp` per pixel, alternately in the two halves):
    the map seen by the camera, BSDF-sampled rays that escape (after the first surface point weighted against the
    texel-by-texel draws, after later ones against next-event estimation), and next-event estimation from the
    second point on. The first surface point's BSDF weight is split into its base colour's slope and offset.
    The scene's materials must be the setup's (its BSDF samples the paths)."""
    import drjit as dr
    from mitsuba.ad.integrators.common import mis_weight  # the power heuristic, as prb weighs its techniques

    mi, height = setup.mi, setup.height
    rows = np.repeat(np.arange(len(setup.pixels)), spp)
    half = np.tile(np.arange(spp) % HALVES, len(setup.pixels))
    n = len(rows)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(int(seed) % SEED_MODULUS, n)
    pixel = setup.pixels[rows]
    w = setup.size[1]
    position = mi.Point2f(((pixel % w + rng.random(n)) / w).astype(np.float32),
                          ((pixel // w + rng.random(n)) / setup.size[0]).astype(np.float32))
    ray, _ = setup.sensor.sample_ray(0.0, 0.5, position, mi.Point2f(0.5, 0.5))
    ctx = mi.BSDFContext()
    beta_slope, beta_offset = dr.zeros(mi.Spectrum, n), dr.full(mi.Spectrum, HALVES / spp, n)
    active = mi.Bool(True)
    prev_si = dr.zeros(mi.SurfaceInteraction3f, n)
    prev_pdf, prev_delta = mi.Float(1.0), mi.Bool(True)

    def keep(mask, direction, weight, drawn_factor=None) -> None:
        dr.eval(mask, direction, beta_slope, beta_offset, weight)
        m = np.asarray(mask, bool)
        scale = np.asarray(weight, np.float64).T[m]
        accumulator.add(rows[m], half[m], np.asarray(direction).T[m], np.asarray(beta_slope).T[m] * scale,
                        np.asarray(beta_offset).T[m] * scale,
                        None if drawn_factor is None else np.asarray(drawn_factor, np.float64)[m])

    for depth in range(max_depth):
        si = setup.scene.ray_intersect(ray, active)
        escaped = active & ~si.is_valid()
        if depth == 1:  # against record_direct's texel-by-texel draws
            mis = dr.select(prev_delta, 1.0, prev_pdf / (prev_pdf + texel_density(ray.d.y, height)))
        else:
            ds = mi.DirectionSample3f(setup.scene, si=si, ref=prev_si)
            mis = mis_weight(prev_pdf, setup.scene.pdf_emitter_direction(prev_si, ds, ~prev_delta))
        if depth == 1 and accumulator.drawn is not None:  # weighed in the drawn texels' columns only
            keep(escaped, ray.d, dr.full(mi.Spectrum, 1.0, n), mis)
        else:
            keep(escaped, ray.d, mi.Spectrum(mis))
        active &= si.is_valid() & (depth + 1 < max_depth)
        if depth + 1 >= max_depth:
            break
        bsdf = si.bsdf(ray)
        if depth >= 1:
            active_em = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            ds, _ = setup.scene.sample_emitter_direction(si, sampler.next_2d(), False, active_em)
            active_em &= ds.pdf != 0.0
            active_em &= ~setup.scene.ray_test(si.spawn_ray(ds.d), active_em)
            value, bsdf_pdf = bsdf.eval_pdf(ctx, si, si.to_local(ds.d), active_em)
            keep(active_em, ds.d, value * mis_weight(ds.pdf, bsdf_pdf) / ds.pdf)
        sample, weight = bsdf.sample(ctx, si, sampler.next_1d(), sampler.next_2d(), active)
        direction = si.to_world(sample.wo)
        if depth == 0:  # the first point's base colour: f(a) / pdf = a (f(1) - f(0)) / pdf + f(0) / pdf
            slope, offset, _ = setup.first_bounce(si, direction, active)
            pdf = dr.select(sample.pdf > 0, sample.pdf, 1.0)
            beta_slope, beta_offset = beta_offset * slope / pdf, beta_offset * offset / pdf
        else:
            beta_slope, beta_offset = beta_slope * weight, beta_offset * weight
        ray = si.spawn_ray(direction)
        prev_si = dr.detach(si, True)
        prev_pdf = sample.pdf
        prev_delta = mi.has_flag(sample.sampled_type, mi.BSDFFlags.Delta)
        active &= (dr.max(beta_slope) != 0) | (dr.max(beta_offset) != 0)
        dr.eval(ray, beta_slope, beta_offset, prev_si, prev_pdf, prev_delta, active)


@dataclass
class ViewTransport:
    """The recording of one view's pixels: slope A and offset B (2, HALVES, 3, pixels, texels), and each
    pixel's albedo lookup (COO rows, texel indices, weights)."""

    matrix: np.ndarray
    pixels: np.ndarray
    """flat indices (row-major in the (h, w) image) of the rows"""
    shape: tuple[int, int]
    lookup: tuple[np.ndarray, np.ndarray, np.ndarray]

    def image(self, env: np.ndarray, albedo: np.ndarray) -> np.ndarray:
        """The view's (h, w, 3) image under an (H, 2H, 3) map and an (R, R, 3) albedo:
        a_p (A L) + B L on the recorded pixels (both halves' mean), 0 elsewhere."""
        rows, index, weight = self.lookup
        seen = np.zeros((len(self.pixels), 3))
        np.add.at(seen, rows, weight[:, None] * albedo.reshape(-1, 3)[index])
        light = env.reshape(-1, 3)
        value = seen * np.einsum("hcpn,nc->pc", self.matrix[0], light) / HALVES \
            + np.einsum("hcpn,nc->pc", self.matrix[1], light) / HALVES
        out = np.zeros((self.shape[0] * self.shape[1], 3))
        out[self.pixels] = value
        return out.reshape(*self.shape, 3)


def record_view(problem: InverseProblem, view: int, materials: MaterialTextures, guide: np.ndarray,
                settings: TransportConfig, seed: int, pixels: np.ndarray | None = None,
                height: int | None = None, every_texel: bool = True) -> ViewTransport:
    """The transport of `pixels` (default: the view's foreground) under `materials` for maps of `height` rows
    (default the problem's; the guide is at the problem's); seeded.
    Without `every_texel` the direct light is drawn texel by texel only for the bright texels, and the BSDF's own
    samples take the rest: a glossy object's narrow lobe finds its texels, at a fraction of the rays."""
    if pixels is None:
        pixels = np.flatnonzero(problem.masks[view].numpy().reshape(-1))
    rng = np.random.default_rng(seed)
    setup = view_setup(problem, view, pixels, materials, guide, height or problem.settings.env_height, rng)
    bright = bright_texels(resize_map(guide, setup.height), BRIGHT_SHARE)
    drawn = None if every_texel else np.isin(np.arange(2 * setup.height ** 2), bright)
    accumulator = Accumulator(len(pixels), setup.height, drawn)
    if every_texel:
        accumulator.matrix = record_direct(setup, settings.direct_spp, seed * 7 + 1, np.arange(accumulator.texels))
    else:
        accumulator.matrix[..., bright] = record_direct(setup, settings.direct_spp, seed * 7 + 1, bright)
    if len(bright):  # the texels that carry most of the light get BRIGHT_SPP draws more, the two estimates mixed
        extra = record_direct(setup, BRIGHT_SPP, seed * 7 + 2, bright)
        share = settings.direct_spp / (settings.direct_spp + BRIGHT_SPP)
        accumulator.matrix[..., bright] = share * accumulator.matrix[..., bright] + (1 - share) * extra
    record_paths(setup, accumulator, settings.spp, problem.renderer.settings.max_depth, seed, rng)
    return ViewTransport(accumulator.matrix, pixels, setup.size, albedo_lookup(setup, problem.settings.texture_size))


def transport_pixels(problem: InverseProblem, limit: int, rng: np.random.Generator) -> dict[int, np.ndarray]:
    """Training view -> the foreground pixels recorded (flat indices): all of them up to `limit` in total, else
    an even random subset of each view's."""
    foreground = {v: np.flatnonzero(problem.masks[v].numpy().reshape(-1)) for v in problem.train_ids}
    total = sum(len(p) for p in foreground.values())
    if total <= limit:
        return foreground
    share = limit / total
    return {v: np.sort(rng.choice(p, max(1, int(round(share * len(p)))), replace=False)) for v, p in foreground.items()}


def record_transport(problem: InverseProblem, materials: MaterialTextures, env: torch.Tensor,
                     settings: TransportConfig, seed: int, max_height: int = ROUGH_TRANSPORT_HEIGHT,
                     every_texel: bool = True) -> LightTransport:
    """The light transport of the training views' foreground pixels (at most settings.pixels of them) under
    `materials`, for maps of `transport_height` rows (at most `max_height`), with next-event directions guided by `env` (the problem's size; module notes)."""
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    chosen = transport_pixels(problem, settings.pixels, rng)
    guide = guide_map(env)
    height = transport_height(problem.settings.env_height, max_height)
    matrices, observed, rows, cols, weights = [], [], [], [], []
    first = 0
    for j, (v, pixels) in enumerate(chosen.items()):
        t = record_view(problem, v, materials, guide, settings, seed * 1009 + j, pixels, height, every_texel)
        matrices.append(torch.from_numpy(t.matrix))
        observed.append(problem.images[v].reshape(-1, 3)[torch.from_numpy(pixels)].double())
        rows.append(t.lookup[0] + first)
        cols.append(t.lookup[1])
        weights.append(t.lookup[2])
        first += len(pixels)
    size = problem.settings.texture_size
    lookup = AlbedoLookup(torch.from_numpy(np.concatenate(rows)), torch.from_numpy(np.concatenate(cols)),
                          torch.from_numpy(np.concatenate(weights)), (first, size * size))
    return LightTransport(torch.cat(matrices, dim=3), lookup, torch.cat(observed), height, materials.detached(),
                          sum(int(problem.masks[v].sum()) for v in problem.train_ids), time.perf_counter() - start)
