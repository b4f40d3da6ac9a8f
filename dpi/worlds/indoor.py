"""Procedural indoor environment maps: a random furnished room, ray cast analytically into an equirect map.

A room is an axis-aligned box [0, W] x [0, Hr] x [0, D] (+Y up) with diffuse walls, floor and
ceiling, furniture boxes standing on the floor, rectangular area emitters (windows whose radiance
is a crop of one procedural outdoor panorama, ceiling panels, small bright lamps) and sometimes an
(invisible) spot light.

The map is rendered deterministically, without Monte Carlo noise: every texel averages
`SUPERSAMPLE` x `SUPERSAMPLE` sub-texel rays from the eye, cast in closed form against the room,
the boxes (ray-slab tests) and the emitters. An emitter seen directly shows its true HDR radiance.
A diffuse point reflects `albedo / pi * (E_direct + AO * E_indirect)`, evaluated once per texel
and surface at the mean of the sub-ray hits there (irradiance is smooth within a surface):

- E_direct: each area emitter by a grid of up to `QUADRATURE` x `QUADRATURE` cells, each a disc
  of the cell's area (Wallace et al. 1989: `cos_s cos_e A / (r^2 + A / pi)`, bounded near the
  emitter), times a shadow test against the boxes; each spot light as a point source with
  Mitsuba's cone falloff and a shadow test. Shadows are smooth penumbrae, never noise.
- E_indirect: the mean interreflected irradiance of a closed room (radiosity with one mean
  albedo a over the total area A, emitted power P): `a P / (A (1 - a))`, uniform.
- AO: a cheap ambient-occlusion factor for points next to furniture (each box as a sphere).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dpi.worlds.raycast import slabs, subtexel_directions

WALL_COLOURS = np.array([[0.85, 0.83, 0.78], [0.7, 0.75, 0.8], [0.8, 0.7, 0.55], [0.6, 0.7, 0.6], [0.9, 0.9, 0.9]])
FLOOR_COLOURS = np.array([[0.45, 0.3, 0.18], [0.3, 0.3, 0.3], [0.6, 0.55, 0.45], [0.2, 0.15, 0.1]])
WARM_WHITE = np.array([1.0, 0.85, 0.65])
SUPERSAMPLE = 3  # sub-texel rays per texel along each axis (anti-aliased edges)
QUADRATURE = 8  # at most this many cells per axis of an area emitter in the direct-light quadrature
QUADRATURE_CELL = 0.15  # metres: a uniform emitter gets cells no longer than this (at most QUADRATURE per axis)
EMITTER_OFFSET = 1e-3  # metres between an emitter and the wall or ceiling it is mounted on
SHADOW_OFFSET = 1e-4  # metres a shadow ray starts above its surface, so the surface does not shadow itself
MIN_AMBIENT_OCCLUSION = 0.3  # a point next to furniture keeps at least this share of the indirect light
WINDOW_TEXELS = 8  # a window shows an 8 x 8 crop of the outdoor panorama's horizon band
DIFFUSER_ALBEDO = 0.8  # reflectance of a panel's or lamp's diffuser (a window reflects nothing: the view passes)


@dataclass(frozen=True)
class RectEmitter:
    """A one-sided Lambertian rectangle emitting towards `u x v` with a radiance texture.

    `radiance` is (h, w, 3): row 0 at the +v edge, column 0 at the -u edge (a uniform panel is 1 x 1).
    `albedo` is the grey diffuse reflectance of its face, so a weak lamp in a bright room is not darker
    than the ceiling around it.
    """

    centre: np.ndarray
    u: np.ndarray
    v: np.ndarray
    half_u: float
    half_v: float
    radiance: np.ndarray
    albedo: float = 0.0

    @property
    def normal(self) -> np.ndarray:
        """Unit normal on the emitting side."""
        return np.cross(self.u, self.v)

    @property
    def area(self) -> float:
        """Area in square metres."""
        return 4.0 * self.half_u * self.half_v

    @property
    def power(self) -> np.ndarray:
        """Emitted RGB flux (W): pi times the mean radiance times the area."""
        return np.pi * self.radiance.mean(axis=(0, 1)) * self.area


@dataclass(frozen=True)
class SpotLight:
    """A point light emitting `intensity` (W/sr) inside a cone of half angle `cutoff` around `axis`."""

    position: np.ndarray
    axis: np.ndarray
    intensity: np.ndarray
    cutoff: float

    @property
    def power(self) -> np.ndarray:
        """Approximate emitted flux: the intensity over the cone out to its mid falloff angle."""
        return self.intensity * 2 * np.pi * (1 - np.cos(0.875 * self.cutoff))


@dataclass(frozen=True)
class Room:
    """A furnished room [0, size] with its lights and the eye point of the map.

    `face_albedo` (6, 3) is ordered x = 0, x = W, y = 0 (floor), y = Hr (ceiling), z = 0, z = D;
    boxes are axis-aligned [box_lo, box_hi] (B, 3) with one albedo (B, 3) each.
    """

    size: np.ndarray
    face_albedo: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    box_albedo: np.ndarray
    emitters: tuple[RectEmitter, ...]
    spots: tuple[SpotLight, ...]
    eye: np.ndarray


@dataclass(frozen=True)
class Hits:
    """What the eye rays (N,) hit: position, surface id, normal, diffuse albedo and emitted radiance.

    Surface ids: 0-5 the room faces (`Room.face_albedo` order), 6 + 6 b + face the faces of box b,
    6 + 6 B + e emitter e (B boxes).
    """

    position: np.ndarray
    surface: np.ndarray
    normal: np.ndarray
    albedo: np.ndarray
    emitted: np.ndarray


# ----------------------------------------------------------------------------------------------
# Random rooms


def wall_frame(size: np.ndarray, face: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """(centre, inward normal, u = up x normal, half extent along u, half height) of wall `face` in (0, 1, 4, 5)."""
    axis, far = divmod(face, 2)
    normal = np.zeros(3)
    normal[axis] = -1.0 if far else 1.0
    centre = size / 2
    centre[axis] = size[axis] if far else 0.0
    u = np.cross([0.0, 1.0, 0.0], normal)
    return centre, normal, u, float(size[2 - axis] / 2), float(size[1] / 2)


def outdoor_band(rng: np.random.Generator, daylight: float) -> np.ndarray:
    """(8, 32, 3) horizon band (polar 45-135 deg) of a procedural outdoor map scaled to median radiance `daylight`.

    The median, not the mean, so that a sun in the band stays an HDR peak on top of the daylight
    instead of dimming every window.
    """
    from dpi.worlds.outdoor import outdoor_envmap

    band = outdoor_envmap(16, rng)[4:12].astype(np.float64)
    return band * daylight / max(float(np.median(band)), 1e-6)


def window_texture(band: np.ndarray, outward: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(8, 8, 3) crop of the panorama band centred near the azimuth a window looks out to."""
    width = band.shape[1]
    phi = np.arctan2(outward[0], -outward[2]) % (2 * np.pi)
    start = int(round(phi / (2 * np.pi) * width - WINDOW_TEXELS / 2)) + int(rng.integers(-2, 3))
    return band[:, (start + np.arange(WINDOW_TEXELS)) % width]


def random_windows(rng: np.random.Generator, size: np.ndarray, daylight: float) -> list[RectEmitter]:
    """1-3 windows on random walls showing one outdoor panorama, or none at night (`daylight` 0)."""
    if daylight <= 0:
        return []
    band = outdoor_band(rng, daylight)
    windows = []
    for _ in range(rng.integers(1, 4)):
        centre, normal, u, hu, hv = wall_frame(size, int(rng.choice([0, 1, 4, 5])))
        w, h = rng.uniform(0.4, min(1.5, hu * 0.8)), rng.uniform(0.4, min(1.0, hv * 0.7))
        pos = centre + normal * EMITTER_OFFSET + u * rng.uniform(-(hu - w), hu - w)
        pos[1] += rng.uniform(-(hv - h) * 0.3, hv - h)
        windows.append(RectEmitter(pos, u, np.array([0.0, 1.0, 0.0]), w, h, window_texture(band, -normal, rng)))
    return windows


def random_panels(rng: np.random.Generator, size: np.ndarray, count: int) -> list[RectEmitter]:
    """`count` warm-white ceiling panels facing down, inside the ceiling."""
    panels = []
    for _ in range(count):
        half_x = rng.uniform(0.15, 0.6)
        half_z = half_x * rng.uniform(0.3, 1.0)
        pos = np.array([rng.uniform(half_x + 0.1, size[0] - half_x - 0.1), size[1] - EMITTER_OFFSET,
                        rng.uniform(half_z + 0.1, size[2] - half_z - 0.1)])
        colour = WARM_WHITE ** rng.uniform(0, 1.5) * rng.uniform(5, 30)
        panels.append(RectEmitter(pos, np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), half_x, half_z,
                                  colour[None, None], DIFFUSER_ALBEDO))
    return panels


def random_lamps(rng: np.random.Generator, size: np.ndarray) -> list[RectEmitter]:
    """In 40 % of rooms 1-4 small bright lamps (12-30 cm, 5-40 W each), on the ceiling (70 %) or as wall sconces."""
    lamps = []
    for _ in range(rng.integers(1, 5) if rng.uniform() < 0.4 else 0):
        half_u, half_v = rng.uniform(0.06, 0.15, 2)
        if rng.uniform() < 0.7:
            pos = np.array([rng.uniform(0.3, size[0] - 0.3), size[1] - EMITTER_OFFSET, rng.uniform(0.3, size[2] - 0.3)])
            u, v = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
        else:
            centre, normal, u, hu, _ = wall_frame(size, int(rng.choice([0, 1, 4, 5])))
            pos = centre + normal * EMITTER_OFFSET + u * rng.uniform(-hu + 0.3, hu - 0.3)
            pos[1] = rng.uniform(1.6, min(2.2, size[1] - 0.3))
            v = np.array([0.0, 1.0, 0.0])
        power = WARM_WHITE ** rng.uniform(0.5, 2.0) * rng.uniform(5, 40)
        radiance = power / (np.pi * 4 * half_u * half_v)
        lamps.append(RectEmitter(pos, u, v, half_u, half_v, radiance[None, None], DIFFUSER_ALBEDO))
    return lamps


def random_spot(rng: np.random.Generator, size: np.ndarray) -> SpotLight:
    """A warm spot light under the ceiling aimed at a random floor point (invisible, as Mitsuba's `spot`)."""
    pos = np.array([rng.uniform(0.3, size[0] - 0.3), size[1] - 0.05, rng.uniform(0.3, size[2] - 0.3)])
    axis = np.array([rng.uniform(0, size[0]), 0.0, rng.uniform(0, size[2])]) - pos
    return SpotLight(pos, axis / np.linalg.norm(axis), WARM_WHITE * rng.uniform(5, 40), np.radians(rng.uniform(15, 40)))


def random_furniture(rng: np.random.Generator, size: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lo, hi, albedo) of 1-6 random boxes standing on the floor."""
    count = rng.integers(1, 7)
    half = np.column_stack([rng.uniform(0.2, 1.0, count), rng.uniform(0.2, 0.9, count), rng.uniform(0.2, 1.0, count)])
    centre = np.column_stack([rng.uniform(half[:, 0], size[0] - half[:, 0]), half[:, 1],
                              rng.uniform(half[:, 2], size[2] - half[:, 2])])
    return centre - half, centre + half, rng.uniform(0.05, 0.8, (count, 3))


def free_eye(rng: np.random.Generator, size: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """An eye point at 1-1.8 m height at least 0.2 m outside every box (best of 100 draws)."""
    for _ in range(100):
        eye = np.array([rng.uniform(0.5, size[0] - 0.5), rng.uniform(1.0, min(1.8, size[1] - 0.3)),
                        rng.uniform(0.5, size[2] - 0.5)])
        if ((eye < lo - 0.2) | (eye > hi + 0.2)).any(axis=1).all():
            break
    return eye


def random_room(rng: np.random.Generator) -> Room:
    """A random furnished, lit room: 3-9 m wide and deep, 2.4-4 m high, daylight (80 %) and/or lamps."""
    size = np.array([rng.uniform(3, 9), rng.uniform(2.4, 4.0), rng.uniform(3, 9)])
    wall = WALL_COLOURS[rng.integers(len(WALL_COLOURS))] * rng.uniform(0.5, 1.0)
    floor = FLOOR_COLOURS[rng.integers(len(FLOOR_COLOURS))] * rng.uniform(0.5, 1.2)
    ceiling = np.full(3, rng.uniform(0.6, 0.9))
    daylight = rng.uniform(3.0, 30.0) * (rng.uniform() < 0.8)
    windows = random_windows(rng, size, daylight)
    panels = random_panels(rng, size, int(rng.integers(0 if windows else 1, 4)))
    lamps = random_lamps(rng, size)
    spots = tuple(random_spot(rng, size) for _ in range(int(rng.uniform() < 0.3)))
    lo, hi, box_albedo = random_furniture(rng, size)
    return Room(size, np.stack([wall, wall, floor, ceiling, wall, wall]), lo, hi, box_albedo,
                tuple(windows + panels + lamps), spots, free_eye(rng, size, lo, hi))


# ----------------------------------------------------------------------------------------------
# Ray casting


def ray_slabs(origin: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, ...]:
    """(entry t, exit t, entry axis, exit axis) (N,) of rays from `origin` along `dirs` (N, 3) through box [lo, hi]."""
    return slabs(origin[None], dirs, lo, hi)


def segment_blocked(start: np.ndarray, end: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Whether the segments start -> end (broadcast, ..., 3) pass through box [lo, hi]."""
    t_near, t_far, _, _ = slabs(start, end - start, lo, hi)
    return np.fmax(t_near, 0.0) <= np.fmin(t_far, 1.0)


def rect_texture(emitter: RectEmitter, s: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Radiance (..., 3) of the emitter's texture at local coordinates s (along u) and t (along v)."""
    h, w = emitter.radiance.shape[:2]
    col = np.clip(((s / emitter.half_u + 1) / 2 * w).astype(int), 0, w - 1)
    row = np.clip(((1 - t / emitter.half_v) / 2 * h).astype(int), 0, h - 1)
    return emitter.radiance[row, col]


def rect_hit(origin: np.ndarray, dirs: np.ndarray, emitter: RectEmitter) -> tuple[np.ndarray, np.ndarray]:
    """(ray parameter (N,), inf where missed; radiance (N, 3)) of rays from `origin` hitting the emitter's front."""
    denom = dirs @ emitter.normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(denom < 0, (emitter.centre - origin) @ emitter.normal / denom, np.inf)
    local = origin + np.where(np.isfinite(t), t, 0.0)[:, None] * dirs - emitter.centre
    s, v = local @ emitter.u, local @ emitter.v
    inside = (np.abs(s) <= emitter.half_u) & (np.abs(v) <= emitter.half_v) & (t > 0)
    radiance = np.zeros_like(dirs)
    radiance[inside] = rect_texture(emitter, s[inside], v[inside])
    return np.where(inside, t, np.inf), radiance


def axis_normals(dirs: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) along `axis` (N,) facing back against the rays `dirs` (N, 3) that hit them."""
    normal = np.zeros_like(dirs)
    rows = np.arange(len(dirs))
    normal[rows, axis] = -np.sign(dirs[rows, axis])
    return normal


def cast_rays(room: Room, dirs: np.ndarray) -> Hits:
    """The first surface or emitter each ray (N, 3) from the eye meets."""
    eye = room.eye
    _, t, _, axis = ray_slabs(eye, dirs, np.zeros(3), room.size)
    normal = axis_normals(dirs, axis)
    surface = 2 * axis + (normal.sum(-1) < 0)
    albedo = room.face_albedo[surface]
    for b, (lo, hi, colour) in enumerate(zip(room.box_lo, room.box_hi, room.box_albedo)):
        t_box, t_exit, box_axis, _ = ray_slabs(eye, dirs, lo, hi)
        closer = (t_box <= t_exit) & (t_box > 0) & (t_box < t)
        box_axis = box_axis[closer]
        t = np.where(closer, t_box, t)
        normal[closer] = axis_normals(dirs[closer], box_axis)
        surface[closer] = 6 + 6 * b + 2 * box_axis + (normal[closer].sum(-1) > 0)
        albedo = np.where(closer[:, None], colour, albedo)
    emitted = np.zeros_like(dirs)
    for e, emitter in enumerate(room.emitters):
        t_e, radiance = rect_hit(eye, dirs, emitter)
        closer = t_e < t
        t = np.where(closer, t_e, t)
        emitted = np.where(closer[:, None], radiance, emitted)
        normal[closer] = emitter.normal
        surface[closer] = 6 + 6 * len(room.box_lo) + e
        albedo[closer] = emitter.albedo
    return Hits(eye + t[:, None] * dirs, surface, normal, albedo, emitted)


# ----------------------------------------------------------------------------------------------
# Shading


def quadrature_size(emitter: RectEmitter) -> int:
    """Cells per axis for an emitter: its texture's resolution, or cells of at most QUADRATURE_CELL metres."""
    cells = np.ceil(2 * max(emitter.half_u, emitter.half_v) / QUADRATURE_CELL)
    return int(np.clip(max(cells, *emitter.radiance.shape[:2]), 2, QUADRATURE))


def quadrature_cells(emitter: RectEmitter, n: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(centres (n*n, 3), radiance (n*n, 3), cell area) of an n x n grid of cells over the emitter."""
    offsets = ((np.arange(n) + 0.5) / n * 2 - 1)
    s, t = np.meshgrid(offsets * emitter.half_u, offsets * emitter.half_v, indexing="ij")
    s, t = s.ravel(), t.ravel()
    centres = emitter.centre + s[:, None] * emitter.u + t[:, None] * emitter.v
    return centres, rect_texture(emitter, s, t), emitter.area / n**2


def shadowed(room: Room, points: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Whether any furniture box blocks the segments points (N, 1, 3) -> targets (K, 3); (N, K)."""
    blocked = np.zeros((len(points), len(targets)), bool)
    lo_pair = np.minimum(points[:, 0], targets.min(0))
    hi_pair = np.maximum(points[:, 0], targets.max(0))
    for lo, hi in zip(room.box_lo, room.box_hi):
        near = ((lo_pair <= hi) & (hi_pair >= lo)).all(-1)  # the box can only block pairs whose bounds it meets
        if near.any():
            blocked[near] |= segment_blocked(points[near], targets[None], lo, hi)
    return blocked


def rect_corners(emitter: RectEmitter) -> np.ndarray:
    """The emitter's four corners (4, 3)."""
    signs = np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]])
    return emitter.centre + (signs * [emitter.half_u, emitter.half_v]) @ np.stack([emitter.u, emitter.v])


def rect_irradiance(room: Room, points: np.ndarray, normals: np.ndarray, emitter: RectEmitter,
                    n: int | None = None) -> np.ndarray:
    """Direct irradiance (N, 3) from an area emitter at points with normals: n x n disc cells, shadowed by boxes.

    Only points in front of the emitter that see part of it above their horizon are integrated.
    """
    centres, radiance, cell_area = quadrature_cells(emitter, n or quadrature_size(emitter))
    irradiance = np.zeros_like(points)
    corners = rect_corners(emitter)
    in_front = (points - emitter.centre) @ emitter.normal > 0
    facing = in_front & (((corners[None] - points[:, None]) * normals[:, None]).sum(-1).max(1) > 0)
    x, nx = points[facing] + SHADOW_OFFSET * normals[facing], normals[facing]
    # (M, K) geometry by matrix products: |c - x|^2, (c - x).n_x, and the height above the emitter's plane.
    r2 = np.maximum((x**2).sum(-1)[:, None] - 2 * x @ centres.T + (centres**2).sum(-1)[None], 0.0)
    r = np.sqrt(r2)
    cos_s = np.maximum((nx @ centres.T - (x * nx).sum(-1)[:, None]) / r, 0.0)
    cos_e = ((x - emitter.centre) @ emitter.normal)[:, None] / r
    weight = cos_s * cos_e * cell_area / (r2 + cell_area / np.pi) * ~shadowed(room, x[:, None], centres)
    irradiance[facing] = weight @ radiance
    return irradiance


def spot_irradiance(room: Room, points: np.ndarray, normals: np.ndarray, spot: SpotLight) -> np.ndarray:
    """Direct irradiance (N, 3) of a spot light: intensity x cone falloff x cos / r^2, shadowed by boxes.

    The falloff is Mitsuba's: 1 inside 3/4 of the cutoff angle, then linear in angle to 0 at the cutoff.
    """
    x = points + SHADOW_OFFSET * normals
    to_light = spot.position - x
    r2 = (to_light**2).sum(-1)
    r = np.sqrt(r2)
    cos_s = np.maximum((to_light * normals).sum(-1) / r, 0.0)
    angle = np.arccos(np.clip(-(to_light @ spot.axis) / r, -1, 1))
    beam = 0.75 * spot.cutoff
    falloff = np.clip((spot.cutoff - angle) / (spot.cutoff - beam), 0.0, 1.0)
    visible = ~shadowed(room, x[:, None], spot.position[None])[:, 0]
    return (falloff * cos_s / r2 * visible)[:, None] * spot.intensity


def direct_irradiance(room: Room, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Irradiance (N, 3) arriving straight from all emitters and spot lights."""
    total = np.zeros_like(points)
    for emitter in room.emitters:
        total += rect_irradiance(room, points, normals, emitter)
    for spot in room.spots:
        total += spot_irradiance(room, points, normals, spot)
    return total


def indirect_irradiance(room: Room) -> np.ndarray:
    """Mean interreflected irradiance (3,) of the closed room: a P / (A (1 - a)).

    P is the emitted flux, A the area (room faces, box tops and sides, less the box footprints,
    and the emitters: windows let light out, diffusers reflect) and a the area-weighted mean albedo.
    """
    w, h, d = room.size
    face_area = np.array([h * d, h * d, w * d, w * d, w * h, w * h])
    extent = room.box_hi - room.box_lo
    footprint = extent[:, 0] * extent[:, 2]
    box_area = footprint + 2 * extent[:, 1] * (extent[:, 0] + extent[:, 2])
    emitter_area = sum(e.area for e in room.emitters)
    reflected = face_area @ room.face_albedo + box_area @ room.box_albedo - footprint.sum() * room.face_albedo[2] \
        + sum(e.albedo * e.area for e in room.emitters)
    area = face_area.sum() + box_area.sum() - footprint.sum() + emitter_area
    a = reflected / area
    power = sum((light.power for light in (*room.emitters, *room.spots)), np.zeros(3))
    return a * power / (area * (1 - a))


def ambient_occlusion(room: Room, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Share (N,) of the indirect light reaching points next to furniture; each box blocks like a sphere.

    A sphere of radius r at distance d, at angle alpha from the normal, covers `(r / d)^2 cos alpha`
    of the cosine-weighted hemisphere.
    """
    occluded = np.zeros(len(points))
    for lo, hi in zip(room.box_lo, room.box_hi):
        to_box = (lo + hi) / 2 - points
        d2 = (to_box**2).sum(-1)
        radius = ((hi - lo) / 2).mean()
        cos_a = np.maximum((to_box * normals).sum(-1) / np.sqrt(d2), 0.0)
        occluded += np.minimum(radius**2 / d2, 1.0) * cos_a
    return np.maximum(1.0 - occluded, MIN_AMBIENT_OCCLUSION)


def irradiance(room: Room, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Total irradiance (N, 3) at diffuse points: direct plus occluded indirect."""
    ambient = ambient_occlusion(room, points, normals)[:, None] * indirect_irradiance(room)
    return direct_irradiance(room, points, normals) + ambient


def shading_points(hits: Hits, texel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (G, 3), normals (G, 3), group of each hit (N,)): one point per (texel, surface), the mean of its hits.

    Irradiance is smooth within a surface, so shading once there is enough; only the
    geometry needs the sub-texel rays (anti-aliased silhouettes and emitter edges).
    """
    key = texel * (hits.surface.max() + 1) + hits.surface
    _, first, group = np.unique(key, return_index=True, return_inverse=True)
    count = np.bincount(group)
    mean = np.stack([np.bincount(group, hits.position[:, k]) for k in range(3)], axis=-1) / count[:, None]
    return mean, hits.normal[first], group


def shade(room: Room, hits: Hits, texel: np.ndarray) -> np.ndarray:
    """Radiance (N, 3) towards the eye: emitted plus albedo / pi x irradiance (only where the albedo is not 0)."""
    diffuse = hits.albedo.max(-1) > 0
    surfaces = Hits(**{name: field[diffuse] for name, field in vars(hits).items()})
    points, normals, group = shading_points(surfaces, texel[diffuse])
    radiance = hits.emitted.copy()
    radiance[diffuse] += surfaces.albedo / np.pi * irradiance(room, points, normals)[group]
    return radiance


def render_room(room: Room, height: int, supersample: int = SUPERSAMPLE) -> np.ndarray:
    """(H, 2H, 3) float32 map of the radiance arriving at the room's eye, each texel a mean over sub-texel rays."""
    dirs = subtexel_directions(height, supersample)
    texel = np.arange(dirs.shape[0] * dirs.shape[1]).repeat(dirs.shape[2])
    radiance = shade(room, cast_rays(room, dirs.reshape(-1, 3)), texel)
    return radiance.reshape(*dirs.shape[:3], 3).mean(2).astype(np.float32)


def indoor_envmaps(height: int, rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` random (count, H, 2H, 3) float32 indoor maps: furnished, lit rooms seen from a point inside."""
    return np.stack([render_room(random_room(rng), height) for _ in range(count)])
