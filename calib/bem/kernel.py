"""The compiled root search of the native BEM, built from ``kernel.c`` at first use.

The root search is most of a BEM solve: about ten evaluations of Ning's residual per section
(two to four for the bracket, the rest Anderson-Björck steps), each a polar look-up, the
loss factors and the induction. In numpy every step of that is a pass over all sections
with a temporary array and a Python round trip per iteration; ``kernel.c`` does the same
arithmetic, in the same order, one section at a time (the bracket, the iteration and the
residual of :mod:`calib.bem.rootfind`, :mod:`calib.bem.residual` and
:meth:`calib.bem.polar_grid.SectionPolars.lookup`). It is used when the effect chain has no
induction stage and its polar stage is empty or a single effect the kernel evaluates itself
(``compiled_polar``: the correction field of every calibration, :class:`calib.bem.stages.CompiledPolar`,
the arithmetic of :meth:`calib.corrections.CorrectionGrid.evaluate`); other polar and induction
effects run Python inside the residual, on the numpy path. It runs the search itself, the
screen for several roots (:mod:`calib.bem.multiple_roots`), the plain section values at the
roots (the last evaluation of each section, reused) and, without a loads-stage effect, the
exact derivatives at the roots (:meth:`SectionKernel.derivatives`: forward mode on the
columns φ, pitch, inflow speed and the field's two probes, what
:func:`calib.bem.sections.section_pass` computes on dual numbers) with the implicit-function
step of :func:`calib.bem.sections.eliminate_phi` (:meth:`SectionKernel.totals`).

Where the time goes (NREL 5-MW C_P surface, 2200 points, 37 400 loaded sections, one core):
about 10 residual evaluations per section at some 50-65 ns each (sin, cos, two exp and acos
for the loss factors, the polar's cubic), i.e. about 0.65 µs per section in the kernel,
plus about 0.3 µs per section of numpy around it (kinematics, status, scatter to full shape).

Build: the C compiler ``$CC`` (else ``cc``, ``gcc``, ``clang``) makes a shared library with
``-O2 -ffp-contract=off`` (no fused multiply-add, no fast-math: the numpy path's rounding),
cached by a hash of the source, the compiler and the platform in ``$CALIB_CACHE/bem_kernel``
(default ``<repo>/.calib_cache/bem_kernel``; a temporary directory when that is not
writable). Never a committed binary. When no compiler is found or the build fails, the
numpy path is used (:func:`status` says why); ``CALIB_BEM_KERNEL=numpy`` forces the numpy
path, ``CALIB_BEM_KERNEL=c`` makes a failed build an error.

References
----------
S.A. Ning, Wind Energy 17 (2014) 1327-1345 (residual, brackets).
N. Anderson, Å. Björck, BIT 13 (1973) 253-264 (the iteration).
"""

from __future__ import annotations

import ctypes
import hashlib
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import uuid
import weakref
from pathlib import Path

import numpy as np

from calib.bem.kernel_chain import node_table
from calib.errors import CalibError

SOURCE = Path(__file__).with_name("kernel.c")
REPO_ROOT = Path(__file__).resolve().parents[2]
FLAGS = ("-O2", "-std=c99", "-ffp-contract=off", "-fno-fast-math", "-fPIC", "-shared")
ENV = "CALIB_BEM_KERNEL"

_state: dict = {}


class KernelBuildError(CalibError, RuntimeError):
    """The compiled BEM kernel was required (``CALIB_BEM_KERNEL=c``) but could not be built."""


class _Problem(ctypes.Structure):
    _fields_ = [("table", ctypes.c_void_p), ("table_row", ctypes.c_void_p), ("n_grid", ctypes.c_int64),
                ("n_stations", ctypes.c_int64), ("step_deg", ctypes.c_double), ("inv_step", ctypes.c_double)]
    _fields_ += [(name, ctypes.c_void_p) for name in ("station", "theta", "vx", "vy", "r", "sigma", "chord", "rho",
                                                      "tip_f", "hub_f", "lam")]
    _fields_ += [("n_blades", ctypes.c_double)]
    _fields_ += [(name, ctypes.c_int) for name in ("tip_loss", "hub_loss", "drag_axial", "drag_tangential",
                                                   "wake_rotation")]
    _fields_ += [(name, ctypes.c_void_p) for name in ("field_alpha", "field_eta", "field_lift", "field_drag")]
    _fields_ += [("field_n_alpha", ctypes.c_int64), ("field_n_eta", ctypes.c_int64), ("field_floor", ctypes.c_double)]
    _fields_ += [(name, ctypes.c_void_p) for name in ("eta_cell", "eta_w0", "eta_w1")]


_ENVELOPES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _compiler() -> str | None:
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def _cache_dir() -> Path:
    root = os.environ.get("CALIB_CACHE")
    return (Path(root) if root else REPO_ROOT / ".calib_cache") / "bem_kernel"


def _build() -> ctypes.CDLL:
    cc = _compiler()
    if cc is None:
        raise KernelBuildError("no C compiler found (set CC, or install gcc or clang)")
    key = hashlib.sha256(SOURCE.read_bytes() + " ".join((cc,) + FLAGS).encode()
                         + f"{sys.platform} {platform.machine()}".encode()).hexdigest()[:16]
    name = f"bem_kernel_{key}.so"
    last = ""
    for base in (_cache_dir(), Path(tempfile.gettempdir()) / "calib_bem_kernel"):
        lib = base / name
        if not lib.exists():
            try:
                base.mkdir(parents=True, exist_ok=True)
                tmp = base / f".{name}.{uuid.uuid4().hex}"
                proc = subprocess.run([cc, *FLAGS, str(SOURCE), "-o", str(tmp), "-lm"], capture_output=True,
                                      text=True, timeout=120)
            except (OSError, subprocess.TimeoutExpired) as exc:
                last = f"{cc} could not build {SOURCE.name} in {base}: {exc}"
                continue
            if proc.returncode != 0:
                raise KernelBuildError(f"{cc} failed on {SOURCE} (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
            os.replace(tmp, lib)              # atomic: concurrent first uses agree
        return ctypes.CDLL(str(lib))
    raise KernelBuildError(last)


def library() -> ctypes.CDLL | None:
    """The loaded kernel, built at first use; None when it is switched off or cannot be built."""
    if "lib" not in _state:
        mode = os.environ.get(ENV, "auto").lower()
        if mode == "numpy":
            _state.update(lib=None, status=f"numpy path ({ENV}=numpy)")
        else:
            try:
                lib = _build()
                ptr = ctypes.c_void_p
                lib.bem_solve.argtypes = [ctypes.POINTER(_Problem), ctypes.c_int64, ctypes.c_double, ctypes.c_double,
                                          ctypes.c_int64] + [ptr] * 11
                lib.bem_solve.restype = None
                lib.bem_residual.argtypes = [ctypes.POINTER(_Problem), ctypes.c_int64, ptr, ptr, ptr]
                lib.bem_residual.restype = None
                lib.bem_residual_partials.argtypes = [ctypes.POINTER(_Problem), ctypes.c_int64, ptr, ptr, ptr, ptr,
                                                      ctypes.c_double, ptr, ptr, ptr]
                lib.bem_residual_partials.restype = None
                lib.bem_polar.argtypes = [ctypes.POINTER(_Problem), ctypes.c_int64, ptr, ptr, ptr, ptr]
                lib.bem_polar.restype = None
                lib.bem_values.argtypes = [ctypes.POINTER(_Problem), ctypes.c_int64, ptr, ptr, ptr, ptr]
                lib.bem_values.restype = None
                lib.bem_screen.argtypes = [ctypes.POINTER(_Problem), ctypes.c_int64, ptr, ptr, ptr, ctypes.c_int64,
                                           ctypes.c_int64, ctypes.c_double, ctypes.c_double, ctypes.c_double, ptr]
                lib.bem_screen.restype = None
                lib.bem_derivatives.argtypes = [ctypes.POINTER(_Problem), ctypes.c_int64, ctypes.c_int64,
                                                ctypes.c_int64] + [ptr] * 4
                lib.bem_derivatives.restype = None
                lib.bem_eta_hats.argtypes = [ctypes.c_int64, ptr, ctypes.c_int64] + [ptr] * 4
                lib.bem_eta_hats.restype = None
                lib.bem_eliminate.argtypes = [ctypes.c_int64, ctypes.c_int64, ptr, ptr, ptr, ctypes.c_int64, ptr]
                lib.bem_eliminate.restype = None
                _state.update(lib=lib, status="compiled kernel")
            except (KernelBuildError, OSError) as exc:
                if mode == "c":
                    raise KernelBuildError(f"{ENV}=c but the BEM kernel is not available: {exc}") from exc
                _state.update(lib=None, status=f"numpy path (kernel not built: {exc})")
    return _state["lib"]


def status() -> str:
    """Which root search the BEM uses, and why not the kernel when it does not."""
    library()
    return _state["status"]


def _ptr(a: np.ndarray) -> int:
    return a.ctypes.data


class SectionKernel:
    """The kernel bound to one batch's sections (arrays kept alive while it is).

    Parameters
    ----------
    lib : ctypes.CDLL
        :func:`library`.
    polars : SectionPolars
    sec : calib.bem.sections.Sections
        The active sections: station index, pitch + twist [rad], velocities [m/s], radius,
        chord [m], local solidity [-], air density [kg/m^3], hub and tip radius, blade count.
    opts : dict
        ``tip_loss``, ``hub_loss``, ``drag_in_axial_induction``, ``drag_in_tangential_induction``,
        ``wake_rotation`` (as :func:`calib.bem.residual.section_equations`).
    field : calib.bem.stages.CompiledPolar, optional
        The chain's polar stage when it is one additive hat-function field (the correction
        field), evaluated after every look-up; None for the tables alone.
    """

    VALUES = ("alpha_deg", "cl", "cd", "residual", "a", "ap", "cn", "ct", "F", "W", "Np", "Tp", "cn_chord",
              "ct_chord")
    """Rows of :meth:`values`."""

    def __init__(self, lib, polars, sec, opts, field=None):
        f8 = lambda x: np.ascontiguousarray(x, dtype=np.float64)   # noqa: E731
        geo = sec.geo
        table, row = node_table(polars)
        h = float(polars.step_deg)
        mantissa, _ = math.frexp(h)
        inv_step = 1.0 / h if mantissa == 0.5 else 0.0       # x / h == x * (1 / h) exactly for a power of two
        B, r = geo.n_blades, geo.r
        with np.errstate(all="ignore"):
            tip_f = B * (geo.tip_radius - r) / (2.0 * r)
            hub_f = B * (r - geo.hub_radius) / (2.0 * geo.hub_radius)
            lam = sec.vy / sec.vx
        per_section = [sec.theta, sec.vx, sec.vy, r, geo.sigma, geo.chord, sec.rho, tip_f, hub_f, lam]
        self._keep = [table, row, np.ascontiguousarray(sec.station, dtype=np.int64)] + [f8(x) for x in per_section]
        self.n = int(sec.station.size)
        self.lib = lib
        self._solved = None
        self.field = field
        section_ptrs = [_ptr(x) for x in self._keep[2:]]
        if field is not None:
            arrays = [f8(x) for x in (field.alpha_nodes_deg, field.eta_nodes, field.lift, field.drag)]
            eta = f8(sec.ctx.eta)
            hats = [np.empty(self.n, dtype=np.int64), np.empty(self.n), np.empty(self.n)]
            lib.bem_eta_hats(self.n, _ptr(arrays[1]), arrays[1].size, _ptr(eta), *(_ptr(x) for x in hats))
            self._keep += arrays + hats
            field_args = [_ptr(x) for x in arrays] + [arrays[0].size, arrays[1].size, float(field.cd_floor)] + \
                [_ptr(x) for x in hats]
        else:
            field_args = [None] * 4 + [0, 0, 0.0] + [None] * 3
        self.problem = _Problem(_ptr(table), _ptr(row), int(table.shape[1]), int(row.size), h, inv_step,
                                *section_ptrs, float(B),
                                int(bool(opts["tip_loss"])), int(bool(opts["hub_loss"])),
                                int(bool(opts["drag_in_axial_induction"])),
                                int(bool(opts["drag_in_tangential_induction"])), int(bool(opts["wake_rotation"])),
                                *field_args)

    def polar(self, index, phi):
        """C_L, C_D [-] at sections ``index`` and inflow angles ``phi`` [rad] (after the field, if any)."""
        index = np.ascontiguousarray(index, dtype=np.int64)
        phi = np.ascontiguousarray(np.broadcast_to(phi, index.shape), dtype=np.float64)
        cl, cd = np.empty(index.shape), np.empty(index.shape)
        self.lib.bem_polar(ctypes.byref(self.problem), index.size, _ptr(index), _ptr(phi), _ptr(cl), _ptr(cd))
        return cl, cd

    def values(self, phi) -> dict:
        """Every section at inflow angle ``phi`` [rad] (its root): :attr:`VALUES` -> ndarray (n,)
        (as :func:`calib.bem.sections.section_pass` without effects and derivatives). Sections
        still at the angle :meth:`solve` ended on reuse that evaluation (the same numbers)."""
        phi = np.ascontiguousarray(phi, dtype=np.float64)
        out = np.empty((len(self.VALUES), self.n))
        solved = self._solved
        self.lib.bem_values(ctypes.byref(self.problem), self.n, _ptr(phi), _ptr(solved[0]) if solved else None,
                            _ptr(solved[1]) if solved else None, _ptr(out))
        return dict(zip(self.VALUES, out))

    DERIVATIVES = ("residual", "Np", "Tp", "cn", "ct", "alpha_deg")
    """Quantities of :meth:`derivatives`."""
    MAX_COLUMNS = 6
    """Most derivative columns :meth:`derivatives` carries (``KMAX`` in kernel.c)."""

    def derivatives(self, phi, k, vx_per_wind, vy_per_wind, probe_column=-1) -> dict:
        """Exact derivatives at the roots ``phi`` [rad] (forward mode, as
        :func:`calib.bem.sections.section_pass` on dual numbers).

        Parameters
        ----------
        phi : ndarray, shape (n,)
        k : int
            Columns: 0 φ [rad], 1 pitch [rad], 2 inflow speed [m/s], then the field's probes
            (additive C_L, C_D) at ``probe_column``, ``probe_column + 1``; at most :attr:`MAX_COLUMNS`.
        vx_per_wind, vy_per_wind : ndarray, shape (n,)
            dV_x/dV, dV_y/dV [-].
        probe_column : int
            -1 without a field.

        Returns
        -------
        dict
            :attr:`DERIVATIVES` -> ndarray (n, k): ∂ quantity / ∂ column (N', T' [N/m], α [deg]).
        """
        if not 3 <= k <= self.MAX_COLUMNS or (self.field is not None) != (probe_column >= 0) \
                or probe_column + 2 > k:
            raise ValueError(f"derivative columns: k = {k}, probe column {probe_column} (field: "
                             f"{self.field is not None}); expected 3 <= k <= {self.MAX_COLUMNS}")
        phi, vxw, vyw = (np.ascontiguousarray(x, dtype=np.float64) for x in (phi, vx_per_wind, vy_per_wind))
        out = np.empty((len(self.DERIVATIVES), self.n, k))
        self.lib.bem_derivatives(ctypes.byref(self.problem), self.n, int(k), int(probe_column), _ptr(phi), _ptr(vxw),
                                 _ptr(vyw), _ptr(out))
        self._derivatives = out
        return dict(zip(self.DERIVATIVES, out))

    def totals(self, converged, sel, shape) -> dict:
        """The implicit-function step on the last :meth:`derivatives` (as
        :func:`calib.bem.sections.eliminate_phi`, the same operations in the same order).

        Parameters
        ----------
        converged : ndarray of bool, shape (n,)
        sel : ndarray of int, shape (n,)
            Flat index of each section in ``shape``.
        shape : tuple
            (n_points, n_sectors, n_stations).

        Returns
        -------
        dict
            ``Np``, ``Tp``, ``cn``, ``ct``, ``alpha_deg`` -> ndarray ``shape + (k - 1,)``: column 0 per
            degree of pitch, 1 per m/s of inflow speed, then the probes; zero off the converged sections.
        """
        d = self._derivatives
        k, size = d.shape[2], int(np.prod(shape))
        full = np.zeros((len(self.DERIVATIVES) - 1, size, k - 1))
        conv = np.ascontiguousarray(converged, dtype=np.uint8)
        sel = np.ascontiguousarray(sel, dtype=np.int64)
        self.lib.bem_eliminate(self.n, k, _ptr(d), _ptr(conv), _ptr(sel), size, _ptr(full))
        return {name: x.reshape(tuple(shape) + (k - 1,)) for name, x in zip(self.DERIVATIVES[1:], full)}

    def residual(self, index, phi) -> np.ndarray:
        """Ning's residual [-] at sections ``index`` and inflow angles ``phi`` [rad] (same shape)."""
        index = np.ascontiguousarray(index, dtype=np.int64)
        phi = np.ascontiguousarray(np.broadcast_to(phi, index.shape), dtype=np.float64)
        out = np.empty(index.shape)
        self.lib.bem_residual(ctypes.byref(self.problem), index.size, _ptr(index), _ptr(phi), _ptr(out))
        return out

    def residual_partials(self, index, phi, cl, cd, rel_step=1e-6):
        """∂R/∂φ [1/rad], ∂R/∂C_L, ∂R/∂C_D [-] at sections ``index`` by one-sided differences
        (as :func:`calib.bem.sections._residual_partials`, which screens for several roots)."""
        index = np.ascontiguousarray(index, dtype=np.int64)
        phi, cl, cd = (np.ascontiguousarray(x, dtype=np.float64) for x in (phi, cl, cd))
        d0, d_cl, d_cd = (np.empty(index.size) for _ in range(3))
        self.lib.bem_residual_partials(ctypes.byref(self.problem), index.size, _ptr(index), _ptr(phi), _ptr(cl),
                                       _ptr(cd), float(rel_step), _ptr(d0), _ptr(d_cl), _ptr(d_cd))
        return d0, d_cl, d_cd

    def screen(self, index, phi, envelope, margin) -> np.ndarray:
        """Sections to search for several roots (bool, shape (n,)): of ``index`` (converged, at
        roots ``phi`` [rad], shape (n,)), those with a negative lift slope in ``envelope`` (a
        :class:`calib.bem.multiple_roots.SlopeEnvelope`) that fail the slope budget of
        :func:`calib.bem.multiple_roots.needs_search` with ``margin``; as the numpy screen of
        :func:`calib.bem.sections.find_roots`."""
        index = np.ascontiguousarray(index, dtype=np.int64)
        phi = np.ascontiguousarray(phi, dtype=np.float64)
        if envelope not in _ENVELOPES:      # the tables' envelope lives as long as its SectionPolars
            _ENVELOPES[envelope] = np.ascontiguousarray(np.stack([envelope.cl_min, envelope.cl_max, envelope.cd_min,
                                                                  envelope.cd_max]), dtype=np.float64)
        stack = _ENVELOPES[envelope]
        search = np.zeros(self.n, dtype=np.uint8)
        self.lib.bem_screen(ctypes.byref(self.problem), index.size, _ptr(index), _ptr(phi), _ptr(stack),
                            int(stack.shape[2]), int(envelope.first_node), float(envelope.step_deg), float(margin),
                            1e-6, _ptr(search))
        return search.astype(bool)

    def solve(self, xtol=1e-12, ftol=1e-12, max_iter=100):
        """Bracket and iteration of every section.

        Returns
        -------
        lo, hi, flo, fhi, found, phi, fphi, iterations
            As :func:`calib.bem.rootfind.bracket` followed by :func:`calib.bem.rootfind.solve_brackets`.
        """
        n = self.n
        lo, hi, flo, fhi, phi, fphi = (np.empty(n) for _ in range(6))
        found = np.empty(n, dtype=np.uint8)
        iters = np.empty(n, dtype=np.int64)
        root = np.empty((9, n))
        order, start = np.empty(n, dtype=np.int64), np.zeros(self.problem.n_stations + 1, dtype=np.int64)
        self.lib.bem_solve(ctypes.byref(self.problem), n, float(xtol), float(ftol), int(max_iter), _ptr(lo),
                           _ptr(hi), _ptr(flo), _ptr(fhi), _ptr(found), _ptr(phi), _ptr(fphi), _ptr(iters),
                           _ptr(root), _ptr(order), _ptr(start))
        self._solved = (phi.copy(), root)
        return lo, hi, flo, fhi, found.astype(bool), phi, fphi, iters
