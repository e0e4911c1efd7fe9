r"""Differentiable rotations of the sphere S² (Loubet et al. 2019, Sec. 4.1).

On S² the change of variables that makes one moving silhouette static is a rotation
R(θ): integrate $f(R(θ) ω, θ)$ instead of $f(ω, θ)$ ($|\det J| = 1$). It must be the
identity at the parameter value θ0 where the gradient is taken, so that the primal
estimate is unchanged sample for sample, and it must move the direction $ω_p$ of one
chosen occluder point exactly: $∂R/∂θ\, ω_{p0} = ∂ω_p/∂θ$.

Construction (the rotation taking the unit vector ``a`` to the unit vector ``b``,
Rodrigues' formula written without trigonometry):

    $R(a → b) = c I + [v]_× + v v^T / (1 + c)$,     $v = a × b$,  $c = a · b$.

With $a = \mathrm{detach}(ω_p)$ and $b = ω_p$ (a Dual), $v = 0$ and $c = 1$ in value,
so R is the identity in value; its derivative is $\dot R = \dot c I + [a × \dot b]_×$ (the
quadratic term has a double zero), and $\dot R a = \dot c a + \dot b (a·a) - a (a·\dot b) = \dot b$ because
$a·\dot b = \dot c = 0$ for a unit vector. Samples are rotated as $R · \mathrm{detach}(ω)$: they are
drawn θ-independently, and only the rotation carries the tangent.

A rotation has one more degree of freedom than the point it follows: a turn about $ω_p$
itself. :meth:`Rotation.following` takes its rate as ``spin`` (an angle of value 0, a Dual);
$\dot R ω$ gains $\dot ψ\, (a × ω)$, the angular velocity being $Ω = a × \dot b + \dot ψ a$.
:mod:`sphere3d.reparam.probes` sets it so that the great circle of a followed edge turns with it.

Floating point: $a × a$ is exactly 0 but $a · a$ is 1 only to rounding, so
:meth:`Rotation.apply` returns $ω + (Rω - \mathrm{detach}(Rω))$: value exactly ω (the
primal stays bit-identical to the naive estimator), tangent exactly that of Rω (computed
in closed form, $\dot c ω + \dot v × ω$, with the products of the Dual evaluation).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, tangent
from sphere3d.live import any_rows, take_rows
from sphere3d.vector import cross, dot, norm

__all__ = ["Rotation", "rotate", "rotation_matrix"]


def rotation_matrix(a: Any, b: Any) -> Any:
    """The matrix $R(a → b) = c I + [v]_× + v v^T / (1 + c)$ of the rotation taking ``a`` to ``b``.

    Parameters
    ----------
    a, b : array_like, shape (..., 3)
        Unit vectors (plain or Dual), not antiparallel ($c = a·b > -1$).

    Returns
    -------
    ndarray or Dual, shape (..., 3, 3)
        Rotation matrices; a Dual when ``a`` or ``b`` is.
    """
    v = cross(a, b)
    c = dot(a, b)
    zero = 0.0 * c
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    # [v]x, the cross-product matrix: [v]x w = v x w
    skew = np.stack(
        [
            np.stack([zero, -vz, vy], axis=-1),
            np.stack([vz, zero, -vx], axis=-1),
            np.stack([-vy, vx, zero], axis=-1),
        ],
        axis=-2,
    )
    eye = np.eye(3) * c[..., None, None]
    outer = v[..., :, None] * v[..., None, :] / (1.0 + c)[..., None, None]
    return eye + skew + outer


def rotate(a: Any, b: Any, omega: Any) -> Any:
    """$R(a → b) ω$ without forming the matrix: $c ω + v × ω + v (v·ω) / (1 + c)$.

    Broadcasts over leading axes; any argument may be a Dual.
    """
    v = cross(a, b)
    c = dot(a, b)
    return c[..., None] * omega + cross(v, omega) + v * (dot(v, omega) / (1.0 + c))[..., None]


@dataclass(frozen=True)
class Rotation:
    r"""A rotation R(θ) that is the identity at θ0 and follows one direction $ω_p(θ)$ exactly.

    Attributes
    ----------
    target : Dual, shape (..., 3)
        $ω_p(θ)$, unit directions; R takes ``detach(target)`` to ``target``.
    active : ndarray of bool, shape (...)
        Where a point was found; elsewhere R is the identity (zero derivative).
    spin : Dual or None, shape (...)
        Angle ψ of a turn about ``target`` (value 0; None: no turn): R is the turn by ψ
        after $R(a → b)$, whose derivative adds $\dot ψ\, (a × ω)$ to $\dot R ω$.
    """

    target: Dual
    active: np.ndarray
    spin: Dual | None = None

    @staticmethod
    def identity(shape: tuple[int, ...], k: int | None = None) -> Rotation:
        """The identity rotation (no point to follow) for ``shape`` integrals (with ``k`` zero tangents:
        for k parameters)."""
        z = np.zeros((*shape, 3))
        z[..., 2] = 1.0
        return Rotation(Dual(z, None, k), np.zeros(shape, dtype=bool))

    @staticmethod
    def following(omega_p: Any, active: np.ndarray | None = None, spin: Any = None) -> Rotation:
        r"""The rotation whose derivative moves $\mathrm{detach}(ω_p)$ like $ω_p$ (Loubet et al. 2019,
        Sec. 4.1), turning about it by the angle ``spin`` (value 0; None: no turn).

        ``omega_p`` need not be unit: it is normalized here, tangent included.
        Where ``active`` is False the direction is replaced by a constant, so the
        rotation there is the identity, also in derivative (and NaNs from an
        undefined $ω_p$ or ``spin`` cannot leak).
        """
        omega_p = omega_p if isinstance(omega_p, Dual) else Dual(omega_p)
        if active is None:
            active = np.ones(omega_p.shape[:-1], dtype=bool)
        length = norm(omega_p.value)
        active = np.asarray(active, dtype=bool) & (length > 0.0) & np.isfinite(length)
        if omega_p.k is not None:  # k tangents: each parameter's slot as its own rotation would be
            return _following_slots(omega_p, active, spin)
        not_finite = any_rows(~np.isfinite(omega_p.tangent).reshape(-1, 3)).reshape(active.shape)
        active = active & ~not_finite
        if spin is not None:
            spin = spin if isinstance(spin, Dual) else Dual(spin)
            active = active & np.isfinite(spin.tangent)
            spin = Dual(np.zeros(active.shape), np.where(active, spin.tangent, 0.0))
        target = Dual(np.zeros(omega_p.shape))
        target.value[..., 2] = 1.0
        # normalized with its tangent (a unit Dual: b·ḃ = 0, which Ṙ a = ḃ relies on), where active
        found = omega_p[active]
        target[active] = found / norm(found)[..., None]
        return Rotation(target, active, spin)

    @property
    def shape(self) -> tuple[int, ...]:
        """Shape of the family of rotations (without the vector axis)."""
        return self.active.shape

    def take(self, index: Any) -> Rotation:
        """The rotations at ``index`` (e.g. one per sample from one per pixel)."""
        return Rotation(
            self.target[index], self.active[index], None if self.spin is None else self.spin[index]
        )

    def apply(self, omega: np.ndarray) -> Dual:
        r"""$R(θ) · \mathrm{detach}(ω)$: value exactly $\mathrm{detach}(ω)$, tangent $\dot R ω$
        (Loubet et al. 2019, Sec. 4.1).

        Parameters
        ----------
        omega : ndarray, shape broadcastable with (..., 3)
            Directions drawn independently of θ (a Dual is detached first).
        """
        omega = detach(omega)
        b = self.target
        if b.k is not None:
            return self._apply_slots(omega)
        if np.shape(omega) == b.shape and not self.active.all():
            # an identity row (inactive: target e_z with tangent +0) has the tangent +0 exactly, so only
            # the active rows are rotated; each row's numbers are those of the whole-array call
            rows = np.flatnonzero(self.active.ravel())
            flat = omega.reshape(-1, 3)
            t = np.zeros(flat.shape)
            if rows.size:
                a, b_dot = (take_rows(f(b).reshape(-1, 3), rows) for f in (detach, tangent))
                omega_rows = take_rows(flat, rows)
                t[rows] = _identity_tangent(a, b_dot, omega_rows)
                if self.spin is not None:  # the turn about a: ψ' (a × ω)
                    t[rows] += tangent(self.spin).ravel()[rows, None] * cross(a, omega_rows)
            return Dual(omega.copy(), t.reshape(omega.shape))
        t = _identity_tangent(detach(b), tangent(b), omega)
        if self.spin is not None:  # the turn about a: ψ' (a × ω)   (zero on the identity rows)
            t = t + tangent(self.spin)[..., None] * cross(detach(b), omega)
        # value exactly ω (R is the identity at θ0 up to rounding in a·a); tangent dR/dθ ω
        return Dual(np.broadcast_to(omega, np.shape(t)).copy(), t)

    def _apply_slots(self, omega: np.ndarray) -> Dual:
        """:meth:`apply` for k parameters: each slot's tangent computed as a single rotation's, on the
        active rows only (an inactive row's tangent is +0 in every slot)."""
        b, k = self.target, self.target.k
        shape = np.broadcast_shapes(np.shape(omega), b.shape)
        flat = np.broadcast_to(omega, shape).reshape(-1, 3)
        rows = np.flatnonzero(np.broadcast_to(self.active, shape[:-1]).ravel())
        t = np.zeros((k, *flat.shape))
        if rows.size:
            a = take_rows(np.broadcast_to(b.value, shape).reshape(-1, 3), rows)
            b_dot = np.broadcast_to(b.tangent, (k, *shape)).reshape(k, -1, 3)[:, rows]
            omega_rows = take_rows(flat, rows)
            turn = None
            if self.spin is not None:  # the turn about a: ψ' (a × ω)
                spin = np.broadcast_to(self.spin.tangent, (k, *shape[:-1])).reshape(k, -1)[:, rows]
                turn = cross(a, omega_rows)
            for i in range(k):  # per parameter, the single rotation's expressions
                t[i, rows] = _identity_tangent(a, b_dot[i], omega_rows)
                if turn is not None:
                    t[i, rows] += spin[i, :, None] * turn
        return Dual(np.broadcast_to(omega, shape).copy(), t.reshape(k, *shape), k)


def _identity_tangent(a: np.ndarray, b_dot: np.ndarray, omega: np.ndarray) -> np.ndarray:
    r"""The tangent of :func:`rotate` ``(a, Dual(a, b_dot), ω)``, R(a → b) at b = a (Loubet et al. 2019,
    Sec. 4.1): $\dot R ω = \dot c ω + \dot v × ω$.

    With $v = a × b$ exactly 0 and $c = a · b$ in value, $\dot c = a · \dot b$, $\dot v = a × \dot b$,
    and the quadratic term $v (v·ω) / (1 + c)$ has a double zero (module docstring). The Dual
    evaluation of :func:`rotate` computes the same products and sums, plus terms that are
    exactly ±0 (a constant's scalar tangent 0, the zero value of v): nonzero components are
    bit for bit the same, a zero may differ in sign. Plain arrays, broadcasting.
    """
    return dot(a, b_dot)[..., None] * omega + cross(cross(a, b_dot), omega)


def _following_slots(omega_p: Dual, active: np.ndarray, spin: Any) -> Rotation:
    r""":meth:`Rotation.following` for k parameters (``omega_p`` with k tangents): one target and one
    spin with k tangent columns, the chosen point's motion in every direction at once. Where one
    parameter's tangent (or spin rate) is not finite, that parameter's slot is the identity there
    (its tangents 0), as its own rotation would be; the other slots keep theirs."""
    k = omega_p.k
    bad = np.any(~np.isfinite(omega_p.tangent), axis=-1)  # (k, ...): per parameter and row
    if spin is not None:
        spin = spin if isinstance(spin, Dual) else Dual(spin, None, k)
        bad = bad | ~np.isfinite(spin.tangent)
        spin = Dual(np.zeros(active.shape), np.where(active & ~bad, spin.tangent, 0.0), k)
    omega_p = Dual(omega_p.value, np.where(bad[..., None], 0.0, omega_p.tangent), k)
    target = Dual(np.zeros(omega_p.shape), None, k)
    target.value[..., 2] = 1.0
    found = omega_p[active]
    target[active] = found / norm(found)[..., None]
    return Rotation(target, active, spin)
