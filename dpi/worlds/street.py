"""Urban street canyons for outdoor env maps, ray cast analytically in numpy from an eye above the road.

A street runs along a random azimuth. Geometry lives in street coordinates (u, v, y): u along the
street, v across it (towards azimuth + 90 degrees), y up, with the eye at (0, 0, eye_height) on the
carriageway. Each side has a front row of building facades (vertical planes v = offset, blocks of
piecewise-constant height, with windows) and a taller row further back; cross streets are gaps in
both. The ground is asphalt with lane markings between brighter pavements; vehicles are boxes.

Shading is Lambertian: sun irradiance times n.s where an analytic shadow ray reaches the sun, plus
the sky the eye sees (buildings occlude it) and one bounce off the geometry the eye sees, both
integrated over the map for each of the five axis normals. Windows add a Fresnel reflection of that
map. Primary rays are supersampled per texel so silhouettes are anti-aliased.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dpi.io.images import with_luminance
from dpi.light.envmap import direction_to_texel
from dpi.worlds.daylight import Daylight, add_sun, irradiance
from dpi.worlds.raycast import slabs, subtexel_directions, texel_mean

SUPERSAMPLE = 2  # primary rays per texel along each axis
STREET_EXTENT = 300.0  # metres along the street, either way, beyond which no building stands
EPSILON = 1e-4  # metres: shadow rays start this far off their surface
NORMALS = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
UP, FORWARD, BACKWARD, RIGHT, LEFT = range(5)  # indices into NORMALS, in street coordinates (u, v, y)
SKY, GROUND, FACADE, VEHICLE = range(4)  # what a primary ray hit
HEIGHT_STYLES = ((5.0, 14.0), (10.0, 30.0), (20.0, 90.0))  # low-rise, mid-rise, high-rise block heights (m)
VEHICLE_SIZES = np.array([[4.4, 1.8, 1.5], [5.5, 2.0, 2.3], [12.0, 2.5, 3.1]])  # car, van, bus: length, width, height
VEHICLE_SHARES = (0.80, 0.15, 0.05)
VEHICLE_COLOURS = np.array([[0.70, 0.70, 0.70], [0.45, 0.45, 0.46], [0.20, 0.20, 0.21], [0.04, 0.04, 0.04],
                            [0.50, 0.05, 0.04], [0.05, 0.12, 0.35], [0.60, 0.50, 0.10], [0.10, 0.25, 0.12]])
WINDOW_INTERIOR = 0.04  # diffuse albedo of what lies behind a window
WINDOW_CENTRE = 0.55  # height of a window's centre within its storey, as a share of the storey
WINDOW_ASPECT = 0.8  # a window's share of its storey's height relative to its share of its bay's width
LANE_WIDTH = 3.25
MARKING_WIDTH = 0.15
MARKING_ALBEDO = np.array([0.65, 0.65, 0.62])
PAVEMENT_COLOURS = np.array([[1.0, 0.98, 0.94], [1.0, 0.93, 0.82], [1.0, 0.62, 0.50]])  # concrete, stone, red paving
SNOW = np.array([0.92, 0.95, 1.0])
SNOW_PROBABILITY = 0.06  # share of scenes whose open ground (or pavements) is snow-covered


@dataclass(frozen=True)
class FacadeMaterial:
    """A kind of building front: wall colour and albedo range, window share and reflectance, how common it is."""

    colour: tuple[float, float, float]
    albedo: tuple[float, float]  # range of the wall's luminance albedo
    window_fraction: tuple[float, float]  # range of the share of a bay's width and a storey's height that is window
    window_f0: float  # window reflectance at normal incidence
    weight: float  # relative frequency


FACADE_MATERIALS = {
    "concrete": FacadeMaterial((0.50, 0.49, 0.47), (0.25, 0.50), (0.35, 0.60), 0.04, 0.30),
    "brick": FacadeMaterial((0.55, 0.30, 0.22), (0.12, 0.28), (0.30, 0.55), 0.04, 0.20),
    "plaster": FacadeMaterial((0.75, 0.68, 0.55), (0.35, 0.65), (0.30, 0.55), 0.04, 0.20),
    "sandstone": FacadeMaterial((0.68, 0.56, 0.40), (0.25, 0.45), (0.30, 0.50), 0.04, 0.10),
    "glass": FacadeMaterial((0.30, 0.34, 0.38), (0.08, 0.20), (0.85, 0.95), 0.20, 0.20),  # curtain wall, dark mullions
}


@dataclass
class Facades:
    """A row of building fronts in the plane v = offset, facing the street; block b spans edges[b] .. edges[b+1]."""

    offset: float  # signed distance across the street from the eye (m)
    edges: np.ndarray  # (B + 1,) block boundaries along the street (m), increasing
    heights: np.ndarray  # (B,) block heights (m); 0 where a cross street passes
    albedo: np.ndarray  # (B, 3) wall albedo
    window_fraction: np.ndarray  # (B,) share of a bay's width and a storey's height that is window
    window_f0: np.ndarray  # (B,) window reflectance at normal incidence
    storey: np.ndarray  # (B,) storey height (m)
    bay: np.ndarray  # (B,) window spacing along the street (m)


@dataclass
class Street:
    """One street canyon in street coordinates (u along, v across, y up), seen from (0, 0, eye_height)."""

    azimuth: float  # envmap azimuth (radians) of the street's +u axis
    eye_height: float  # m
    road: tuple[float, float]  # v range of the carriageway (m)
    lanes: int
    building_lines: tuple[float, float]  # v of the left and right front rows: pavements lie between them and the road
    rows: list[Facades]
    vehicles_lo: np.ndarray  # (K, 3) lower corners of vehicle boxes (u, v, y)
    vehicles_hi: np.ndarray  # (K, 3) upper corners
    vehicle_albedo: np.ndarray  # (K, 3)
    asphalt: np.ndarray  # (3,) albedo of road and cross streets
    pavement: np.ndarray  # (3,) albedo of pavements


def street_frame(azimuth: float) -> np.ndarray:
    """(3, 3) rotation taking world directions (+Y up) to street coordinates (u, v, y)."""
    along = [np.sin(azimuth), 0.0, -np.cos(azimuth)]
    across = [np.cos(azimuth), 0.0, np.sin(azimuth)]
    return np.array([along, across, [0.0, 1.0, 0.0]])


def random_facades(rng: np.random.Generator, offset: float, style: tuple[float, float], crossings: np.ndarray,
                   taller: float) -> Facades:
    """A row of blocks 6-30 m wide at `offset`, heights from `style` times `taller`, cut by cross streets (C, 2)."""
    widths = rng.uniform(6.0, 30.0, size=int(2 * STREET_EXTENT / 6) + 1)
    edges = np.concatenate([[-STREET_EXTENT], -STREET_EXTENT + np.cumsum(widths)])
    edges = edges[: np.searchsorted(edges, STREET_EXTENT) + 1]
    count = edges.size - 1
    heights = rng.uniform(*style, size=count) * taller
    middle = (edges[:-1] + edges[1:]) / 2
    in_crossing = ((middle[:, None] > crossings[:, 0]) & (middle[:, None] < crossings[:, 1])).any(1)
    kinds = list(FACADE_MATERIALS.values())
    weights = np.array([kind.weight for kind in kinds])
    chosen = [kinds[i] for i in rng.choice(len(kinds), size=count, p=weights / weights.sum())]
    albedo = with_luminance([m.colour for m in chosen], [rng.uniform(*m.albedo) for m in chosen])
    return Facades(offset=offset, edges=edges, heights=np.where(in_crossing, 0.0, heights), albedo=albedo,
                   window_fraction=np.array([rng.uniform(*m.window_fraction) for m in chosen]),
                   window_f0=np.array([m.window_f0 for m in chosen]), storey=rng.uniform(2.9, 4.0, size=count),
                   bay=rng.uniform(2.0, 4.5, size=count))


def random_crossings(rng: np.random.Generator) -> np.ndarray:
    """(C, 2) u intervals of cross streets: one every 50-160 m, 10-25 m wide, the first within 60 m of the eye."""
    start = rng.uniform(-60.0, 60.0)
    ahead = start + np.cumsum(rng.uniform(50.0, 160.0, size=8))
    behind = start - np.cumsum(rng.uniform(50.0, 160.0, size=8))
    centres = np.concatenate([behind[::-1], [start], ahead])
    widths = rng.uniform(10.0, 25.0, size=centres.size)
    return np.stack([centres - widths / 2, centres + widths / 2], axis=1)


def random_vehicles(rng: np.random.Generator, road: tuple[float, float], lanes: int,
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Up to 10 vehicle boxes in the lanes, apart from each other and 2.5 m or more from the eye:
    lower and upper corners (K, 3) and albedos (K, 3)."""
    lo, hi = [], []
    for _ in range(int(rng.integers(0, 11))):
        size = VEHICLE_SIZES[rng.choice(len(VEHICLE_SIZES), p=VEHICLE_SHARES)]
        centre_v = road[0] + (rng.integers(lanes) + 0.5) * (road[1] - road[0]) / lanes
        box_lo = np.array([rng.uniform(-60.0, 60.0) - size[0] / 2, centre_v - size[1] / 2, 0.0])
        box_hi = box_lo + size
        clear_of_eye = np.linalg.norm(np.clip(0.0, box_lo[:2], box_hi[:2])) > 2.5
        clear_of_others = all((box_lo[:2] > h[:2] + 0.5).any() or (box_hi[:2] < l[:2] - 0.5).any()
                              for l, h in zip(lo, hi))
        if clear_of_eye and clear_of_others:
            lo.append(box_lo)
            hi.append(box_hi)
    albedo = VEHICLE_COLOURS[rng.integers(len(VEHICLE_COLOURS), size=len(lo))]
    return np.reshape(lo, (-1, 3)), np.reshape(hi, (-1, 3)), albedo


def random_street(rng: np.random.Generator) -> Street:
    """A random street: 1-4 lanes, pavements 1.5-6 m, low- to high-rise blocks on both sides, cross streets, traffic."""
    lanes = int(rng.integers(1, 5))
    width = lanes * LANE_WIDTH
    road_left = -rng.uniform(0.15, 0.85) * width
    road = (road_left, road_left + width)
    lines = (road[0] - rng.uniform(1.5, 6.0), road[1] + rng.uniform(1.5, 6.0))
    style = HEIGHT_STYLES[rng.integers(len(HEIGHT_STYLES))]
    crossings = random_crossings(rng)
    rows = [random_facades(rng, line, style, crossings, taller=1.0) for line in lines]
    rows += [random_facades(rng, line + np.sign(line) * rng.uniform(15.0, 40.0), style, crossings,
                            taller=rng.uniform(1.0, 2.0)) for line in lines]
    vehicles_lo, vehicles_hi, vehicle_albedo = random_vehicles(rng, road, lanes)
    asphalt, pavement = random_street_albedos(rng)
    return Street(azimuth=float(rng.uniform(0, 2 * np.pi)), eye_height=float(rng.uniform(1.5, 2.0)), road=road,
                  lanes=lanes, building_lines=lines, rows=rows, vehicles_lo=vehicles_lo, vehicles_hi=vehicles_hi,
                  vehicle_albedo=vehicle_albedo, asphalt=asphalt, pavement=pavement)


def random_street_albedos(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """RGB albedos of the asphalt (0.05-0.12) and of the pavements (concrete, stone or red paving, 0.15-0.4); with
    probability SNOW_PROBABILITY snowy pavements (0.6-0.8) beside a slushy road (0.15-0.3)."""
    if rng.uniform() < SNOW_PROBABILITY:
        return with_luminance(SNOW, rng.uniform(0.15, 0.3)), with_luminance(SNOW, rng.uniform(0.6, 0.8))
    pavement = with_luminance(PAVEMENT_COLOURS[rng.integers(len(PAVEMENT_COLOURS))], rng.uniform(0.15, 0.4))
    return with_luminance([1.0, 1.0, 1.02], rng.uniform(0.05, 0.12)), pavement


def facade_heights(row: Facades, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Block index (clipped) and building height (0 beyond the row's ends) at positions u along the street."""
    index = np.searchsorted(row.edges, u, side="right") - 1
    inside = (index >= 0) & (index < row.heights.size)
    index = np.clip(index, 0, row.heights.size - 1)
    return index, np.where(inside, row.heights[index], 0.0)


def facade_distance(row: Facades, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Ray parameter (N,) where rays (street coordinates) meet the row's facades; inf where they pass."""
    t = np.full(dirs.shape[0], np.inf)
    np.divide(row.offset - origins[:, 1], dirs[:, 1], out=t, where=dirs[:, 1] != 0)
    ahead = np.isfinite(t) & (t > 0)
    along = np.where(ahead, t, 0.0)
    y = origins[:, 2] + along * dirs[:, 2]
    _, top = facade_heights(row, origins[:, 0] + along * dirs[:, 0])
    return np.where(ahead & (y >= 0) & (y < top), t, np.inf)


def box_distance(lo: np.ndarray, hi: np.ndarray, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Ray parameter (K, N) where rays enter boxes with corners lo, hi (K, 3); inf where they miss."""
    entry, exit_, _, _ = slabs(origins[None], dirs[None], lo[:, None], hi[:, None])
    return np.where((entry < exit_) & (entry > 0), entry, np.inf)


def box_face(lo: np.ndarray, hi: np.ndarray, points: np.ndarray) -> np.ndarray:
    """NORMALS index (N,) of the face of its box (corners lo, hi (N, 3)) that each surface point (N, 3) lies on."""
    gaps = np.abs(np.stack([points[:, 0] - lo[:, 0], points[:, 0] - hi[:, 0], points[:, 1] - lo[:, 1],
                            points[:, 1] - hi[:, 1], points[:, 2] - hi[:, 2]], axis=1))
    return np.array([BACKWARD, FORWARD, LEFT, RIGHT, UP])[gaps.argmin(1)]


def occluded(street: Street, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Whether rays (N,) from origins (street coordinates) towards dirs hit any facade or vehicle."""
    blocked = np.zeros(origins.shape[0], dtype=bool)
    for row in street.rows:
        blocked |= np.isfinite(facade_distance(row, origins, dirs))
    if street.vehicles_lo.size:
        blocked |= np.isfinite(box_distance(street.vehicles_lo, street.vehicles_hi, origins, dirs)).any(0)
    return blocked


@dataclass
class Hits:
    """First surfaces met by primary rays: what (SKY/GROUND/FACADE/VEHICLE), which row or box, where, facing where."""

    surface: np.ndarray  # (N,) int
    index: np.ndarray  # (N,) facade row or vehicle box
    points: np.ndarray  # (N, 3) street coordinates
    normal: np.ndarray  # (N,) NORMALS index


def cast(street: Street, dirs: np.ndarray) -> Hits:
    """Nearest surface along each primary ray (N, 3) (street coordinates) from the eye."""
    count = dirs.shape[0]
    eye = np.broadcast_to([0.0, 0.0, street.eye_height], (count, 3))
    ground = np.where(dirs[:, 2] < 0, street.eye_height / np.maximum(-dirs[:, 2], 1e-12), np.inf)
    facades = np.stack([facade_distance(row, eye, dirs) for row in street.rows])
    boxes = box_distance(street.vehicles_lo, street.vehicles_hi, eye, dirs)
    candidates = np.concatenate([ground[None], facades, boxes])
    nearest = candidates.argmin(0)
    t = candidates[nearest, np.arange(count)]
    rows = len(street.rows)
    kind = np.where(nearest == 0, GROUND, np.where(nearest <= rows, FACADE, VEHICLE))
    surface = np.where(np.isinf(t), SKY, kind)
    index = np.where(surface == FACADE, nearest - 1, np.where(surface == VEHICLE, nearest - 1 - rows, 0))
    points = eye + np.where(np.isinf(t), 0.0, t)[:, None] * dirs
    offsets = np.array([row.offset for row in street.rows])
    normal = np.where(surface == FACADE, np.where(offsets[np.clip(index, 0, rows - 1)] > 0, LEFT, RIGHT), UP)
    on_box = surface == VEHICLE
    box = index[on_box]
    normal[on_box] = box_face(street.vehicles_lo[box], street.vehicles_hi[box], points[on_box])
    return Hits(surface=surface, index=index, points=points, normal=normal)


def ground_albedo(street: Street, points: np.ndarray) -> np.ndarray:
    """(N, 3) albedo of ground points: asphalt with dashed lane and solid edge lines, pavements, cross streets."""
    u, v = points[:, 0], points[:, 1]
    on_road = (v >= street.road[0]) & (v <= street.road[1])
    on_pavement = ~on_road & (v > street.building_lines[0]) & (v < street.building_lines[1])
    lane_lines = street.road[0] + np.arange(1, street.lanes) * (street.road[1] - street.road[0]) / street.lanes
    dashed = (np.abs(v[:, None] - lane_lines).min(1, initial=np.inf) < MARKING_WIDTH / 2) & (np.mod(u, 9.0) < 3.0)
    edge = np.abs(v[:, None] - (np.array(street.road) + [0.3, -0.3])).min(1) < MARKING_WIDTH / 2
    albedo = np.where(on_pavement[:, None], street.pavement, street.asphalt)
    return np.where((on_road & (dashed | edge))[:, None], MARKING_ALBEDO, albedo)


def facade_albedo(street: Street, hits: Hits) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) diffuse albedo and (N,) window F0 (0 on walls) at facade hits: a window grid on each block's wall."""
    albedo, f0 = np.zeros((hits.index.size, 3)), np.zeros(hits.index.size)
    for r, row in enumerate(street.rows):
        mine = (hits.surface == FACADE) & (hits.index == r)
        u, y = hits.points[mine, 0], hits.points[mine, 2]
        block, _ = facade_heights(row, u)
        fraction = row.window_fraction[block]
        across = np.abs(np.mod((u - row.edges[block]) / row.bay[block], 1.0) - 0.5)
        up = np.abs(np.mod(y / row.storey[block], 1.0) - WINDOW_CENTRE)
        window = (across < fraction / 2) & (up < fraction / 2 * WINDOW_ASPECT) & (y > 0.3)
        albedo[mine] = np.where(window[:, None], WINDOW_INTERIOR, row.albedo[block])
        f0[mine] = np.where(window, row.window_f0[block], 0.0)
    return albedo, f0


def vehicle_albedo(street: Street, hits: Hits) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) diffuse albedo and (N,) glass F0 at vehicle hits: paint, with a band of windows on the sides."""
    mine = hits.surface == VEHICLE
    box = hits.index[mine]
    low, high = street.vehicles_lo[box, 2], street.vehicles_hi[box, 2]
    glass = (hits.normal[mine] != UP) & (hits.points[mine, 2] > low + 0.55 * (high - low))
    albedo, f0 = np.zeros((hits.index.size, 3)), np.zeros(hits.index.size)
    albedo[mine] = np.where(glass[:, None], WINDOW_INTERIOR, street.vehicle_albedo[box])
    f0[mine] = np.where(glass, 0.04, 0.0)
    return albedo, f0


def surface_albedo(street: Street, hits: Hits) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) diffuse albedo and (N,) F0 of the glass (0 elsewhere) at every hit; sky rays get zeros."""
    albedo, f0 = facade_albedo(street, hits)
    vehicle, vehicle_f0 = vehicle_albedo(street, hits)
    ground = ground_albedo(street, hits.points)
    albedo = np.where((hits.surface == GROUND)[:, None], ground, albedo + vehicle)
    return albedo, f0 + vehicle_f0


def sun_irradiance(street: Street, light: Daylight, hits: Hits, frame: np.ndarray) -> np.ndarray:
    """(N, 3) direct sun irradiance on every hit: E_sun n.s where a shadow ray reaches the sun, else 0."""
    sun = frame @ light.sun
    cosine = np.maximum(NORMALS[hits.normal] @ sun, 0.0) * (hits.surface != SKY)
    facing = cosine > 0
    if not facing.any() or not light.sun_irradiance.any():
        return np.zeros((hits.surface.size, 3))
    origins = hits.points[facing] + EPSILON * NORMALS[hits.normal[facing]]
    lit = np.zeros_like(facing)
    lit[facing] = ~occluded(street, origins, np.broadcast_to(sun, origins.shape))
    return (cosine * lit)[:, None] * light.sun_irradiance


def fresnel(f0: np.ndarray, cosine: np.ndarray) -> np.ndarray:
    """Schlick's reflectance for normal-incidence reflectance f0 at incidence cosines."""
    return f0 + (1 - f0) * (1 - cosine) ** 5


def window_reflection(dirs: np.ndarray, normals: np.ndarray, f0: np.ndarray, env: np.ndarray,
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Fresnel reflectance (N,) of rays (N, 3) meeting glass (f0 > 0; 0 elsewhere) and the radiance (N, 3) of `env`
    in their mirrored directions."""
    cosine = (dirs * normals).sum(-1)
    row, col = direction_to_texel(dirs - 2 * cosine[:, None] * normals, env.shape[0])
    return fresnel(f0, np.abs(cosine)) * (f0 > 0), env[row, col]


def street_envmap(light: Daylight, street: Street) -> np.ndarray:
    """(H, 2H, 3) map seen from the eye of a street canyon under `light`; the sun is there unless something hides it."""
    height = light.sky.shape[0]
    frame = street_frame(street.azimuth)
    dirs = subtexel_directions(height, SUPERSAMPLE).reshape(-1, 3)
    hits = cast(street, dirs @ frame.T)
    solid = (hits.surface != SKY)[:, None]
    sky = light.sky * (1 - texel_mean(solid.astype(float), height, SUPERSAMPLE))
    albedo, f0 = surface_albedo(street, hits)
    world_normals = NORMALS @ frame  # the street's axis normals in world coordinates
    sun = sun_irradiance(street, light, hits, frame)
    ambient = irradiance(sky, world_normals)[hits.normal]
    lit_once = albedo * (ambient + sun) / np.pi * solid
    first = texel_mean(lit_once, height, SUPERSAMPLE)  # geometry lit once, for the bounce
    ambient = ambient + irradiance(first, world_normals)[hits.normal]
    reflectance, reflected = window_reflection(dirs, world_normals[hits.normal], f0, sky + first)
    radiance = (1 - reflectance[:, None]) * albedo * (ambient + sun) / np.pi + reflectance[:, None] * reflected
    env = sky + texel_mean(radiance * solid, height, SUPERSAMPLE)
    eye = np.array([[0.0, 0.0, street.eye_height]])
    return add_sun(env, light, visible=not occluded(street, eye, (frame @ light.sun)[None])[0])
