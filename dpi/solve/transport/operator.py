"""The recorded light transport as a torch operator: images under any map and albedo, their residuals and the
normal equations of the views (dpi.solve.transport.record says how it is recorded)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import torch

from dpi.solve.materials import MaterialTextures


def apply_light(matrix: torch.Tensor, light: torch.Tensor) -> torch.Tensor:
    """(..., 3, P, N) transports times a (3, N) map, per channel: (..., 3, P) (a batch of matrix-vector products
    over contiguous blocks, at memory speed)."""
    batch = matrix.reshape(-1, 3, *matrix.shape[-2:])
    vectors = light.to(matrix.dtype).expand(batch.shape[0], 3, -1).reshape(-1, matrix.shape[-1], 1)
    out = torch.bmm(batch.reshape(-1, *matrix.shape[-2:]), vectors)
    return out.reshape(*matrix.shape[:-1])


@dataclass
class AlbedoLookup:
    """The albedo each recorded pixel sees, as a sparse (pixels, texels) matrix of bilinear weights in COO form:
    `apply` maps a texture to the pixels, `adjoint` back."""

    rows: torch.Tensor
    texels: torch.Tensor
    weights: torch.Tensor
    shape: tuple[int, int]

    def apply(self, texture: torch.Tensor) -> torch.Tensor:
        """(texels, C) -> (pixels, C) (differentiable)."""
        out = torch.zeros(self.shape[0], texture.shape[1], dtype=texture.dtype)
        return out.index_add(0, self.rows, self.weights.to(texture.dtype)[:, None] * texture[self.texels])

    def adjoint(self, values: torch.Tensor) -> torch.Tensor:
        """(pixels, C) -> (texels, C): the transpose of `apply`."""
        out = torch.zeros(self.shape[1], values.shape[1], dtype=values.dtype)
        return out.index_add(0, self.texels, self.weights.to(values.dtype)[:, None] * values[self.rows])

    def squared(self) -> "AlbedoLookup":
        """The matrix of squared weights (for the diagonal of W^T D W)."""
        return AlbedoLookup(self.rows, self.texels, self.weights.square(), self.shape)


@dataclass
class NormalEquations:
    """A sum of squared residuals as a quadratic form in the map: sum_p (M_p L - y_p)^2 = L^T G L - 2 b^T L + k
    per channel, G (3, N, N), b (3, N), over `count` residuals (pixels x channels)."""

    gram: torch.Tensor
    rhs: torch.Tensor
    constant: float
    count: int

    def apply(self, x: torch.Tensor) -> torch.Tensor:
        """G x per channel, x (3, N)."""
        return torch.bmm(self.gram, x[:, :, None].to(self.gram.dtype))[..., 0]

    def diagonal(self) -> torch.Tensor:
        """(3, N) the diagonal of G (a preconditioner's)."""
        return self.gram.diagonal(dim1=1, dim2=2)

    def energy(self, x: torch.Tensor) -> float:
        """x^T G x summed over the channels, x (3, N)."""
        return float((x * self.apply(x)).sum())

    def sum_squares(self, env: torch.Tensor) -> torch.Tensor:
        """Sum of squared residuals under an (H, 2H, 3) map (differentiable)."""
        flat = env.reshape(-1, 3).T.to(torch.float64)
        quadratic = (flat * self.apply(flat)).sum()
        return quadratic - 2 * (self.rhs * flat).sum() + self.constant

    def mean_squares(self, env: torch.Tensor) -> torch.Tensor:
        """Mean squared residual per pixel and channel (differentiable, at least 0)."""
        return (self.sum_squares(env) / self.count).clamp_min(0).to(env.dtype)

    def exposure(self, env: torch.Tensor) -> float:
        """The least-squares global scale c of the map (c L fits best; 1 when none is positive)."""
        flat = env.detach().reshape(-1, 3).T.to(torch.float64)
        den = self.energy(flat)
        num = float((self.rhs * flat).sum())
        return num / den if den > 0 and num > 0 else 1.0


@dataclass
class LightTransport:
    """The training views' transport at the recorded pixels (module notes): slope A and offset B,
    (2, HALVES, 3, P, N) float32; the albedo each pixel sees (a sparse (P, R^2) lookup); the views' values (P, 3);
    the materials it was recorded with."""

    matrix: torch.Tensor
    lookup: AlbedoLookup
    observed: torch.Tensor
    height: int
    materials: MaterialTextures
    foreground: int
    """foreground pixels of the training views (the recorded ones are all of them or a subset)"""
    seconds: float
    """wall time of the recording"""

    @property
    def slope(self) -> torch.Tensor:
        """A: (HALVES, 3, P, N)."""
        return self.matrix[0]

    @property
    def offset(self) -> torch.Tensor:
        """B: (HALVES, 3, P, N)."""
        return self.matrix[1]

    @property
    def pixels(self) -> int:
        """Recorded pixels."""
        return self.observed.shape[0]

    @property
    def weight(self) -> float:
        """Foreground pixels per recorded pixel: a data term over the subset, times this, stands for all."""
        return self.foreground / self.pixels

    @property
    def nbytes(self) -> int:
        """Memory the recording keeps."""
        return sum(t.element_size() * t.numel() for t in (self.matrix, self.observed, self.lookup.rows,
                                                          self.lookup.texels, self.lookup.weights))

    def seen_albedo(self, albedo: torch.Tensor) -> torch.Tensor:
        """(P, 3) the albedo each recorded pixel sees, from an (R, R, 3) texture (differentiable)."""
        return self.lookup.apply(albedo.reshape(-1, 3))

    def halves(self, env: torch.Tensor, albedo: torch.Tensor) -> torch.Tensor:
        """(HALVES, P, 3) each half's image of the recorded pixels under a map and an albedo (differentiable)."""
        light = env.reshape(-1, 3).T
        a = self.seen_albedo(albedo).T.to(self.slope.dtype)
        return (a * apply_light(self.slope, light) + apply_light(self.offset, light)).transpose(-1, -2)

    @cached_property
    def mean(self) -> torch.Tensor:
        """The halves' mean transport: (2, 3, P, N) (slope, offset), kept once asked for."""
        return self.matrix.mean(dim=1)

    def image(self, env: torch.Tensor, albedo: torch.Tensor) -> torch.Tensor:
        """(P, 3) the recorded pixels' image under a map and an albedo: the halves' mean (differentiable)."""
        light = env.reshape(-1, 3).T
        a = self.seen_albedo(albedo).T.to(self.matrix.dtype)
        return (a * apply_light(self.mean[0], light) + apply_light(self.mean[1], light)).T

    def sum_squares(self, env: torch.Tensor, albedo: torch.Tensor) -> torch.Tensor:
        """Sum over the recorded pixels of the squared residual, without the recording's noise: the product of
        the two halves' residuals (unbiased; module notes). A value to compare, not a loss to descend: it is not
        bounded below (halves that disagree make it negative), so `fit_loss` is the one to optimise."""
        first, second = self.halves(env, albedo) - self.observed.to(self.slope.dtype)
        return (first * second).sum()

    def fit_loss(self, env: torch.Tensor, albedo: torch.Tensor) -> torch.Tensor:
        """Sum over the recorded pixels of the squared residual of the halves' mean image (differentiable): convex,
        and above `sum_squares` by the recording's variance (an optimiser following the halves' product would
        pull them apart, into the recording's noise)."""
        return (self.image(env, albedo) - self.observed.to(self.slope.dtype)).square().sum()

    def image_equations(self, albedo: torch.Tensor) -> NormalEquations:
        """`fit_loss` as normal equations in the map under a fixed albedo: of the halves' mean transport
        M_p = a_p A_p + B_p, G = M^T M and b = M^T y."""
        a = self.seen_albedo(albedo.detach()).T[:, :, None].to(self.slope.dtype)
        matrix = a * self.mean[0] + self.mean[1]  # (3, P, N)
        observed = self.observed.T
        rhs = (matrix.transpose(1, 2) @ observed.to(matrix.dtype)[:, :, None])[..., 0].double()
        return NormalEquations((matrix.transpose(1, 2) @ matrix).double(), rhs,
                               float(observed.double().square().sum()), observed.numel())


def resize_map(env: np.ndarray, height: int) -> np.ndarray:
    """An (H, 2H, 3) map area-resampled to `height` rows (itself when it has them)."""
    from dpi.io.images import resize

    return env if env.shape[0] == height else resize(torch.from_numpy(env), height, 2 * height).numpy()
