"""Events along a branch of steady gaits: detected between neighbouring points, located by a root solve.

Each event is the zero of a scalar test function of the orbit, continuous along the branch:

- `FOLD`: $\\det(M - I)$ (a real multiplier at $+1$) where the tangent's $d\\lambda/ds$ also changes
  sign; `BRANCH_POINT` where it does not;
- `PERIOD_DOUBLING`: $\\det(M + I)$ (a real multiplier at $-1$; complex pairs contribute
  $|\\mu + 1|^2 > 0$);
- `TORUS` (Neimark-Sacker): $\\det(M^{(2)} - I)$, with $M^{(2)}$ the second compound matrix of $M$
  (its $2 \\times 2$ minors), whose eigenvalues are the products $\\mu_i \\mu_j$, $i < j$: zero where a
  complex pair reaches the unit circle ($\\mu \\bar\\mu = 1$; its other factors pair into
  $|\\mu\\mu_k - 1|^2 > 0$). It vanishes too where two real multipliers' product is 1 (a neutral
  saddle, no bifurcation), so a sign change counts only where both points have a complex pair whose
  modulus crosses 1 (`complex_radius`);
- `SWITCH`: another change of the switching structure (the number of switches or, under
  `contact="hop"`, of landings per period: a velocity or a height grazing zero; or, with the same
  counts, the order of the bodies' changes of mode or the bodies that change: two events passing
  each other), bracketed by two points but not located;
- `SSL_SL`: the slip margin, the smallest $|F_i| - \\mu_s n_i$ at a slipping mass's velocity zero
  (eq. 7; [`Gait`][]`.slip_margin`). At such an instant a mass sticks where it is negative and
  reverses where it is positive; as a stick interval shrinks to nothing, the margin at its
  start goes to zero, and it stays the same smooth function of the orbit on the SL side;
- `LIFTOFF`: the smallest normal force on the orbit, $\\min_t \\min(N_1, N_2)$ (eq. 5). Under the
  strict reading there is no orbit beyond it: the branch's failed step bounds it, counted as
  $-\\infty$.

A sign change between two points brackets a root. A switching event is solved directly as the
point where the branch meets the switching surface, $\\Phi_k(y; \\lambda) = y$ and $g(y, \\lambda) = 0$,
by Newton's method with the forward-mode gradient of $g$ (quadratic convergence; at a corner of the
branch, where the two sides' step sequences differ, it still finds the one point both sides share).
Otherwise (and where that fails) the root is bracketed on the chord between the two points: the
point at distance $s$ along the chord is corrected onto the branch on the hyperplane normal to the
chord (so that folds are located too), and $s$ is found by the Illinois variant of regula falsi
(bisection where a value is infinite), until the bracket is narrower than `LAM_TOL` in the
parameter. A test function that jumps across zero instead (a switching structure changing the
multipliers at once, a stick interval born at a grazing velocity zero) is located as well, to the
same tolerance, and reported with `smooth` False.
"""

from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array
from .._results import BODIES, PAPER


LAM_TOL = 1e-10
"""Width of the final bracket in the parameter, relative to $\\max(1, |\\lambda|)$ (float64; float32: 1e-5)."""

SMOOTH = 1e-5
"""A located test function smaller than this in magnitude crossed zero continuously (the test functions
are of order one; the step sequence of the engine changes where the switching structure does, which
makes them jump by the truncation error, about 1e-7 at `dt = 0.03`)."""

MAX_ITER = 60
"""Root-solve iterations per event."""


class EventKind:
    """Kinds of [`BranchEvents`][] (module docstring); -1 pads a branch's list."""

    FOLD = 0
    PERIOD_DOUBLING = 1
    BRANCH_POINT = 2
    SSL_SL = 3
    LIFTOFF = 4
    SWITCH = 5
    TORUS = 6


NAMES = {0: "FOLD", 1: "PERIOD_DOUBLING", 2: "BRANCH_POINT", 3: "SSL_SL", 4: "LIFTOFF", 5: "SWITCH", 6: "TORUS"}

REAL_TOL = 1e-8
"""A multiplier whose imaginary part is below this times its modulus counts as real (`complex_radius`)."""


def compound(M: np.ndarray) -> np.ndarray:
    """The second compound matrix of `M` (`(..., S, S)` -> `(..., m, m)`, $m = S(S-1)/2$): its entry
    $((p, q), (r, s))$, $p < q$, $r < s$, is the minor $M_{pr} M_{qs} - M_{ps} M_{qr}$. Its eigenvalues
    are the products $\\mu_i \\mu_j$, $i < j$, of the eigenvalues of `M` (Binet-Cauchy)."""
    p, q = np.triu_indices(M.shape[-1], 1)
    rows = lambda a, b: M[..., a[:, None], b[None, :]]
    return rows(p, p) * rows(q, q) - rows(p, q) * rows(q, p)


def torus_function(M: np.ndarray) -> np.ndarray:
    """$\\det(M^{(2)} - I)$, the `TORUS` test function (module docstring)."""
    C = compound(M)
    return np.asarray(np.linalg.det(C - np.eye(C.shape[-1])))


def complex_radius(multipliers: np.ndarray) -> np.ndarray:
    """The largest modulus of a complex (non-real) multiplier, per point (NaN where all are real)."""
    mod = np.abs(multipliers)
    cplx = np.abs(np.imag(multipliers)) > REAL_TOL * mod
    return np.asarray(np.where(cplx.any(-1), np.max(np.where(cplx, mod, -np.inf), axis=-1, initial=-np.inf), np.nan))


def _column(name: str, index: int) -> property:
    """The paper's name of one column of the events' `state`, refused on another mechanism."""

    def get(events: "BranchEvents") -> Array:
        if events.names != PAPER:
            raise ValueError(f"`{name}` is the paper's name for the two-mass model; read `state[..., {index}]`.")
        return events.state[..., index]

    return property(get, doc=f"The paper's `{name}` at each event: `state[..., {index}]` (the paper's model only).")


class BranchEvents(eqx.Module):
    """Located events per branch, `batch + (m,)`, padded with `kind` -1 (NaN numbers).

    - `kind`: [`EventKind`][]; `index`: the branch point before the event.
    - `lam`: the parameter at the event; `lam_error`: the width of the final bracket.
    - `state`: the orbit's section state there, `(m, S)`; `multipliers`: its Floquet multipliers `(m, S)`.
    - `value`: the test function there (near 0 for a smooth crossing).
    - `smooth`: the test function crossed zero continuously (False: it jumped across).
    - `located`: the root solve converged to `LAM_TOL` (`SWITCH` events are not located: `lam` is
      the middle of the two points and `lam_error` half their distance).
    - `turn`: the branch reverses its direction in $\\lambda$ across the event (at a switching
      event: a non-smooth fold, where two pieces of the branch meet at a corner).
    - `names`: `"paper"` for the paper's model (then `u`, `v1`, `v2` name the columns of `state`;
      they raise a `ValueError` on other mechanisms), else `"bodies"`.
    """

    kind: Array
    index: Array
    lam: Array
    lam_error: Array
    state: Array
    multipliers: Array
    value: Array
    smooth: Array
    located: Array
    turn: Array
    names: str = eqx.field(static=True, default=BODIES)

    u = _column("u", 0)
    v1 = _column("v1", 1)
    v2 = _column("v2", 2)


def _functional(kind: int, r, contact: str) -> np.ndarray:
    """The test function of `kind` at the corrector's result `r` (NaN where it failed)."""
    S = r.z.shape[-1] - 1
    M = r.J[:, :S, :S]
    if kind in (EventKind.FOLD, EventKind.BRANCH_POINT):
        g = np.linalg.det(M - np.eye(S))
    elif kind == EventKind.PERIOD_DOUBLING:
        g = np.linalg.det(M + np.eye(S))
    elif kind == EventKind.TORUS:
        g = torus_function(M)
    elif kind == EventKind.SSL_SL:
        g = r.out.margin
    else:
        g = r.out.n_min
    g = np.where(r.done, g, np.nan)
    if kind == EventKind.LIFTOFF and contact == "strict":
        g = np.where(~r.done & (r.out.status == 1), -np.inf, g)  # Status.LIFTOFF
    return g


def _brackets(d: dict, status: np.ndarray, failed_at: np.ndarray) -> list[list[tuple]]:
    """Per branch: `(kind, j, z_a, z_b, g_a, g_b)` for each event between points j and j + 1.

    A change of the slip margin's or the smallest normal force's sign is a switching event. The
    multipliers jump where the switching structure changes, so a sign change of $\\det(M \\mp I)$
    is a (smooth) fold or period doubling only between points of the same structure; another change
    of the switch or landing count, or of the order of the bodies' mode changes (`sequence`), is
    reported as `SWITCH`. A sign change of the torus function counts where
    a complex pair's modulus crosses 1 between the two points (not a neutral saddle)."""
    B = d["valid"].shape[0]
    out: list[list[tuple]] = [[] for _ in range(B)]
    for i in range(B):
        n = int(d["count"][i])
        z = d["z"][i]
        for j in range(n - 1):
            pair = lambda name: (d[name][i, j], d[name][i, j + 1])
            row = lambda kind, g: (kind, j, z[j], z[j + 1], g[0], g[1], d["J"][i, j], d["J"][i, j + 1])
            m, nm, sw, nl, sq = pair("margin"), pair("n_min"), pair("n_switch"), pair("n_land"), pair("sequence")
            if (m[0] > 0) != (m[1] > 0):
                out[i].append(row(EventKind.SSL_SL, m))
            if (nm[0] > 0) != (nm[1] > 0):
                out[i].append(row(EventKind.LIFTOFF, nm))
            if (m[0] > 0) != (m[1] > 0) or (nm[0] > 0) != (nm[1] > 0):
                continue
            if sw[0] != sw[1] or nl[0] != nl[1] or sq[0] != sq[1]:
                out[i].append(row(EventKind.SWITCH, (np.nan, np.nan)))
                continue
            dp, dm, dt, rc = pair("det_plus"), pair("det_minus"), pair("det_torus"), pair("complex_radius")
            if (dp[0] > 0) != (dp[1] > 0):
                out[i].append(row(EventKind.PERIOD_DOUBLING, dp))
            if (dt[0] > 0) != (dt[1] > 0) and (rc[0] > 1) != (rc[1] > 1) and np.all(np.isfinite(rc)):
                out[i].append(row(EventKind.TORUS, dt))
            if (dm[0] > 0) != (dm[1] > 0):
                fold = (d["t"][i, j, -1] > 0) != (d["t"][i, j + 1, -1] > 0)
                out[i].append(row(EventKind.FOLD if fold else EventKind.BRANCH_POINT, dm))
        if status[i] == 4 and n > 0:  # BranchStatus.LIFTOFF: the failed step is beyond the lift-off
            Jn = d["J"][i, n - 1]
            out[i].append(
                (EventKind.LIFTOFF, n - 1, z[n - 1], failed_at[i], d["n_min"][i, n - 1], -np.inf, Jn, Jn * np.nan)
            )
    return out


def _surface(solve, rows: list[tuple | None], lam_tol: float) -> list[dict | None]:
    """A switching event as the solution of $\\Phi_k(y; \\lambda) = y$, $g(y, \\lambda) = 0$: Newton's
    method, the test function $g$ (slip margin or smallest normal force) linearised with its
    forward-mode gradient at each iterate, from the bracket's end where $|g|$ is smaller. The point
    where the branch meets the switching surface, on whichever side the iterates lie (a corner
    too). `None` where it does not converge within the bracket (the caller then brackets)."""
    B = len(rows)
    go = np.array([r is not None for r in rows])
    if not go.any():
        return [None] * B
    S = _size(rows)
    pad = (EventKind.SSL_SL, 0, np.zeros(S + 1), np.ones(S + 1), 1.0, -1.0, np.zeros((S + 2, S + 1)),
           np.zeros((S + 2, S + 1)))  # fmt: skip
    kind, j, za, zb, ga, gb, Ja, Jb = (np.array(x) for x in zip(*[r if r is not None else pad for r in rows]))
    row = np.where(kind == EventKind.SSL_SL, S, S + 1)
    first = (np.abs(ga) <= np.abs(np.where(np.isfinite(gb), gb, np.inf))) | ~np.all(np.isfinite(Jb), axis=(1, 2))
    z = np.where(first[:, None], za, zb)
    J = np.where(first[:, None, None], Ja, Jb)
    g = np.where(first, ga, gb).astype(float)
    grad = J[np.arange(B), row]
    span = np.linalg.norm(zb - za, axis=-1)
    ok, conv = go & np.isfinite(g) & np.all(np.isfinite(grad), axis=-1), np.zeros(B, bool)
    dlam = np.full(B, np.inf)
    for _ in range(12):
        active = ok & ~conv
        if not np.any(active):
            break
        with np.errstate(all="ignore"):
            norm = np.linalg.norm(grad, axis=-1)
            c = grad / np.where(norm > 0, norm, 1)[:, None]
            zref = z - (g / np.where(norm > 0, norm, 1))[:, None] * c
        zref = np.where(active[:, None], zref, z)
        r = solve(zref, zref, c, active)
        g_new = np.where(row == S, r.out.margin, r.out.n_min)
        good = active & r.done & np.isfinite(g_new) & (np.linalg.norm(r.z - za, axis=-1) <= 2 * span)
        ok &= ~(active & ~good)
        dlam = np.where(good, np.abs(solve.scale * (r.z[:, S] - z[:, S])), dlam)
        z = np.where(good[:, None], r.z, z)
        J = np.where(good[:, None, None], r.J, J)
        g = np.where(good, g_new, g)
        grad = J[np.arange(B), row]
        lam = solve.lam0 + solve.scale * z[:, S]
        conv |= good & (dlam <= lam_tol * np.maximum(1, np.abs(lam))) & (np.abs(g) <= 1e-9)
    out: list[dict | None] = []
    for i in range(B):
        if not (go[i] and ok[i] and conv[i]):
            out.append(None)
            continue
        M = J[i, :S, :S]
        mult = np.linalg.eigvals(M)
        out.append(
            dict(
                kind=int(kind[i]),
                index=int(j[i]),
                lam=float(solve.lam0[i] + solve.scale[i] * z[i, S]),
                lam_error=float(dlam[i]),
                state=z[i, :S],
                multipliers=mult[np.argsort(-np.abs(mult))],
                value=float(abs(g[i])),
                smooth=True,
                located=True,
            )  # fmt: skip
        )
    return out


def _locate(solve, rows: list[tuple | None], contact: str, lam_tol: float) -> list[dict | None]:
    """Illinois regula falsi on the chord of each lane's bracket, all lanes per corrector call."""
    B = len(rows)
    go = np.array([r is not None for r in rows])
    S = _size(rows)
    pad = (0, 0, np.zeros(S + 1), np.ones(S + 1), 1.0, -1.0, np.zeros((S + 2, S + 1)), np.zeros((S + 2, S + 1)))
    kind, j, za, zb, ga, gb, _, _ = (np.array(x) for x in zip(*[r if r is not None else pad for r in rows]))
    L = np.linalg.norm(zb - za, axis=-1)
    e = (zb - za) / np.where(L > 0, L, 1)[:, None]
    lo, hi = np.zeros(B), L.copy()
    glo, ghi = ga.astype(float), gb.astype(float)
    last = np.zeros(B, int)  # which end the previous step replaced (Illinois)
    best_z = np.where((np.abs(ga) <= np.abs(gb))[:, None], za, zb)
    best_J = np.full((B, S + 2, S + 1), np.nan)
    best_g = np.minimum(np.abs(ga), np.abs(gb))
    width = lambda: np.abs(solve.scale * e[:, S]) * (hi - lo)
    lam_at = lambda zz: solve.lam0 + solve.scale * zz[:, S]
    ok = go.copy()
    for _ in range(MAX_ITER):
        active = ok & (width() > lam_tol * np.maximum(1, np.abs(lam_at(best_z))))
        if not np.any(active):
            break
        finite = np.isfinite(glo) & np.isfinite(ghi) & (glo != ghi)
        with np.errstate(all="ignore"):
            s = np.where(finite, hi - ghi * (hi - lo) / (ghi - glo), 0.5 * (lo + hi))
        inside = (s > lo) & (s < hi)
        s = np.where(inside, s, 0.5 * (lo + hi))
        zs = za + s[:, None] * e
        r = solve(zs, zs, e, active)
        res = np.empty(B)
        for kd in set(kind[active].tolist()):
            sel = kind == kd
            res[sel] = _functional(int(kd), r, contact)[sel]
        failed = active & np.isnan(res)
        ok = ok & ~failed
        step = active & ~failed
        to_hi = step & ((res > 0) == (ghi > 0))
        to_lo = step & ~to_hi
        glo = np.where(to_hi & (last == 1), glo / 2, glo)
        ghi = np.where(to_lo & (last == -1), ghi / 2, ghi)
        hi, ghi = np.where(to_hi, s, hi), np.where(to_hi, res, ghi)
        lo, glo = np.where(to_lo, s, lo), np.where(to_lo, res, glo)
        last = np.where(to_hi, 1, np.where(to_lo, -1, last))
        better = step & ((np.abs(res) <= best_g) | np.isnan(best_J[:, 0, 0]))
        best_z = np.where(better[:, None], r.z, best_z)
        best_J = np.where(better[:, None, None], r.J, best_J)
        best_g = np.where(better, np.abs(res), best_g)
        ok = ok & ~(step & (res == 0))  # an exact zero: done
    located = go & ok & ((width() <= lam_tol * np.maximum(1, np.abs(lam_at(best_z)))) | (best_g == 0))
    out: list[dict | None] = []
    for i in range(B):
        if rows[i] is None:
            out.append(None)
            continue
        M = best_J[i, :S, :S]
        mult = np.linalg.eigvals(M) if np.all(np.isfinite(M)) else np.full(S, np.nan + 0j)
        out.append(
            dict(
                kind=int(kind[i]),
                index=int(j[i]),
                lam=float(lam_at(best_z)[i]),
                lam_error=float(width()[i]),
                state=best_z[i, :S],
                multipliers=mult[np.argsort(-np.abs(mult))],
                value=float(best_g[i]),
                smooth=bool(best_g[i] <= SMOOTH),
                located=bool(located[i]),
            )  # fmt: skip
        )
    return out


LOCATABLE = frozenset({EventKind.FOLD, EventKind.PERIOD_DOUBLING, EventKind.BRANCH_POINT, EventKind.SSL_SL,
                       EventKind.LIFTOFF, EventKind.TORUS})  # fmt: skip
"""The kinds with a test function (`SWITCH` has none)."""


def kinds(locate: bool | Sequence[str]) -> frozenset[int]:
    """The event kinds to locate: all (`True`), none (`False`), or those named."""
    if isinstance(locate, bool):
        return LOCATABLE if locate else frozenset()
    codes = {name: code for code, name in NAMES.items() if code in LOCATABLE}
    if isinstance(locate, str) or any(name not in codes for name in locate):
        raise ValueError(f"locate must be a bool or a sequence of event kinds among {sorted(codes)}, got {locate!r}.")
    return frozenset(codes[name] for name in locate)


def find_events(d: dict, status: np.ndarray, failed_at: np.ndarray, solve, contact: str, locate: frozenset[int],
                paper: bool = False):  # fmt: skip
    """The events of each branch (module docstring); those of the kinds `locate` located, all branches'
    root solves advancing together. `paper`: also the paper's names `u, v1, v2` of the state."""
    S = d["z"].shape[-1] - 1
    rows = _brackets(d, status, failed_at)
    B = len(rows)
    lam_tol = LAM_TOL if np.dtype(solve.dtype).itemsize == 8 else 1e-5
    todo = [[x for x in branch if x[0] in locate] for branch in rows]
    done: list[dict[int, dict]] = [{} for _ in range(B)]
    switching = (EventKind.SSL_SL, EventKind.LIFTOFF)
    for r in range(max((len(x) for x in todo), default=0)):
        lane = [x[r] if r < len(x) else None for x in todo]
        newton = _surface(solve, [x if x is not None and x[0] in switching else None for x in lane], lam_tol)
        rest = [x if x is not None and newton[i] is None else None for i, x in enumerate(lane)]
        bracketed: list[dict | None] = [None] * B
        if any(x is not None for x in rest):
            bracketed = _locate(solve, rest, contact, lam_tol)
        for i, x in enumerate(lane):
            ev = newton[i] if newton[i] is not None else bracketed[i]
            if ev is not None:
                done[i][id(x)] = ev
    found: list[list[dict]] = [[] for _ in range(B)]
    for i, branch in enumerate(rows):
        for x in branch:
            ev = done[i].get(id(x)) or _unlocated(x, solve, i)
            j = x[1]
            t = d["t"][i, j : j + 2, -1]
            ev["turn"] = bool(j + 1 < d["count"][i] and (t[0] > 0) != (t[1] > 0))
            found[i].append(ev)
    m = max(1, max(len(f) for f in found))
    fill = dict(kind=-1, index=-1, lam=np.nan, lam_error=np.nan, state=np.full(S, np.nan),
                multipliers=np.full(S, np.nan + 0j), value=np.nan, smooth=False, located=False, turn=False)  # fmt: skip
    table = {key: [[(f[q] if q < len(f) else fill)[key] for q in range(m)] for f in found] for key in fill}
    return BranchEvents(
        kind=jnp.asarray(table["kind"], jnp.int32),
        index=jnp.asarray(table["index"], jnp.int32),
        **{
            key: jnp.asarray(np.asarray(table[key], float), solve.dtype)
            for key in ("lam", "lam_error", "state", "value")
        },
        multipliers=jnp.asarray(np.asarray(table["multipliers"])),
        smooth=jnp.asarray(table["smooth"], bool),
        located=jnp.asarray(table["located"], bool),
        turn=jnp.asarray(table["turn"], bool),
        names=PAPER if paper else BODIES,
    )


def _unlocated(row: tuple, solve, i: int) -> dict:
    """An event bracketed but not located: the linear interpolation of its test function (or the
    middle), with the distance to the farther point as its error."""
    kind, j, za, zb, ga, gb, _, _ = row
    w = ga / (ga - gb) if np.isfinite(ga) and np.isfinite(gb) and ga != gb else 0.5
    z = za + w * (zb - za)
    lam = solve.lam0[i] + solve.scale[i] * z[-1]
    S = len(z) - 1
    err = abs(solve.scale[i] * (zb[S] - za[S])) * max(w, 1 - w)
    return dict(kind=kind, index=j, lam=lam, lam_error=err, state=z[:S],
                multipliers=np.full(S, np.nan + 0j), value=np.nan, smooth=False, located=False)  # fmt: skip


def _size(rows: list[tuple | None]) -> int:
    """The section state's length $S$ of the brackets `rows` (their points have $S + 1$ unknowns)."""
    return next(len(r[2]) for r in rows if r is not None) - 1
