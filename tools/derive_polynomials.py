"""Derive the Case-I polynomials of the single-sensor problem and print ``_coefficients.py``.

This script is the source of ``src/activetrack/solvers/_coefficients.py``: the committed module is
exactly what it prints::

    python tools/derive_polynomials.py > src/activetrack/solvers/_coefficients.py
    python tools/derive_polynomials.py --check   # exit status 1 if the committed file differs

Derivation (paper Section IV-A, Case I; equation numbers of the paper):

1. Objective (22) in the eigenbasis of the prior information (Lemma 2), with
   ``a = 1/sigma_d^2``, ``b = 1/sigma_theta^2``, ``Delta = x^2 + y^2``::

       f0 = tr(M^-1) = tr(M) / det(M) = P / Q,
       P  = Delta ((l1 + l2 + a) Delta + b),
       Q  = l1 l2 Delta^2 + a b Delta + a Delta (l1 y^2 + l2 x^2) + b (l1 x^2 + l2 y^2).

2. Stationarity on the speed circle (31): ``(s - c)^T C(pi/2) grad f0(s) = 0``. Clearing the
   denominator ``Delta^2 Q^2`` leaves ``2 Delta^2 f1`` with the 8th-order polynomial ``f1`` of
   (32)::

       f1 = b3 x y Delta^3 + (a8 x + a7 y + b2) x y Delta^2
            + (a6 x^3 + a5 x^2 y + a4 x y^2 + a3 y^3 + b1 x y) Delta + (a2 x + a1 y) x y,

   whose coefficients ``alpha1..8`` (``a*``) and ``beta1..3`` (``b*``) are found by matching
   monomials; the match is unique and exact (asserted below). They depend on
   ``l1, l2, a, b, c1, c2`` only.

3. Numerics-friendly variables. Lengths are measured in units of ``r`` (so ``r = 1``; then
   ``b`` stands for ``b / r^2`` and ``c`` for ``c / r``) and the speed circle (30) is
   centred: ``x = c1 + X``, ``y = c2 + Y``, so ``f2 = X^2 + Y^2 - 1`` and real critical
   points have ``X`` in ``[-1, 1]``. On the circle ``Delta = |c|^2 + 1 + 2 c1 X + 2 c2 Y`` is
   linear, so ``f1`` restricted to the circle equals a 5th-order polynomial ``g(X, Y)``
   (this is why Bezout gives 10, not 16, intersections).

4. Reducing ``Y^2 -> 1 - X^2`` gives ``g = g0(X) + g1(X) Y`` (same values on the circle, so
   the same resultant with the monic-in-``Y`` ``f2``). The Sylvester resultant (33) of
   ``g1 Y + g0`` and ``Y^2 + X^2 - 1`` in ``Y`` (a 3x3 Sylvester determinant) is the
   10th-order ``f3(X) = g0^2 + (X^2 - 1) g1^2 = sum_j gamma_j X^j``. It is checked against
   ``sympy.resultant`` of the unreduced 8th-order ``f1(x, y)`` and ``f2(x, y)`` for random
   rational parameters (the paper's ``f3(x)`` is this polynomial after ``x = c1 + r X``).

The generated code only uses ``+ - *`` so it runs on floats (the scalar solver) and on
numpy arrays (the batched solver) alike. ``alpha_beta`` and ``sylvester_gammas`` are
emitted through ``sympy.cse``; ``circle_reduction`` is a straight-line program that
multiplies eq. (32), in Horner form in ``Delta``, out in the ``g0 + g1 Y`` representation
(about 215 operations instead of ~775 for the expanded coefficients); it is checked
identical to the expanded step-3/4 coefficients before it is printed.
"""

from __future__ import annotations

import argparse
import difflib
import random
import sys
from pathlib import Path

import sympy as sp
from sympy.printing.str import StrPrinter

ROOT = Path(__file__).resolve().parents[1]
TARGET = ROOT / "src" / "activetrack" / "solvers" / "_coefficients.py"

x, y, X, Y = sp.symbols("x y X Y", real=True)
l1, l2, a, b, c1, c2 = sp.symbols("l1 l2 a b c1 c2", real=True)
ALPHA = sp.symbols("alpha1:9")
BETA = sp.symbols("beta1:4")
G0 = sp.symbols("h0:6")  # coefficients of g0(X), lowest degree first
G1 = sp.symbols("k0:5")  # coefficients of g1(X), lowest degree first


def objective() -> sp.Expr:
    """Return f0 of eq. (22) in the eigenbasis, built from the information matrix."""
    s = sp.Matrix([x, y])
    J = sp.Matrix([[0, 1], [-1, 0]])  # J = C(-pi/2), eq. (9)
    d = x**2 + y**2
    M = sp.diag(l1, l2) + a * s * s.T / d + b * (J * s) * (J * s).T / d**2
    return sp.cancel(M.trace() / M.det())


def f1_polynomial(f0: sp.Expr) -> sp.Poly:
    """Return the 8th-order polynomial f1 of eq. (32): eq. (31) with denominators cleared."""
    grad = sp.Matrix([sp.diff(f0, x), sp.diff(f0, y)])
    rot = sp.Matrix([[0, -1], [1, 0]])  # C(pi/2)
    lhs = ((sp.Matrix([x - c1, y - c2]).T * rot * grad)[0]).together()
    num, _ = sp.fraction(lhs)
    factors = [f for f, _ in sp.factor_list(num)[1] if sp.Poly(f, x, y).total_degree() == 8]
    assert len(factors) == 1, "expected one 8th-order factor besides powers of Delta"
    poly = sp.Poly(factors[0], x, y)
    others = sp.factor_list(num)[1]
    assert all(sp.expand(f - (x**2 + y**2)) == 0 for f, _ in others if f != factors[0])
    return poly


def eq32_form(alpha: tuple, beta: tuple, xx: sp.Expr, yy: sp.Expr, delta: sp.Expr) -> sp.Expr:
    """Return the right-hand side of eq. (32) for the given coefficients and ``Delta``."""
    a1, a2, a3, a4, a5, a6, a7, a8 = alpha
    b1, b2, b3 = beta
    return (
        b3 * xx * yy * delta**3
        + (a8 * xx + a7 * yy + b2) * xx * yy * delta**2
        + (a6 * xx**3 + a5 * xx**2 * yy + a4 * xx * yy**2 + a3 * yy**3 + b1 * xx * yy) * delta
        + (a2 * xx + a1 * yy) * xx * yy
    )


def fit_alpha_beta(f1: sp.Poly) -> list[sp.Expr]:
    """Return [alpha1..8, beta1..3] with eq32_form == f1 identically (unique solution)."""
    form = eq32_form(ALPHA, BETA, x, y, x**2 + y**2)
    eqs = sp.Poly(sp.expand(f1.as_expr() - form), x, y).coeffs()
    sols = sp.solve(eqs, list(ALPHA) + list(BETA), dict=True)
    assert len(sols) == 1 and len(sols[0]) == 11, "eq. (32) fit is not unique"
    coeffs = [sp.factor(sols[0][v]) for v in list(ALPHA) + list(BETA)]
    check = eq32_form(coeffs[:8], coeffs[8:], x, y, x**2 + y**2) - f1.as_expr()
    assert sp.expand(check) == 0
    return coeffs


def circle_reduction() -> tuple[list[sp.Expr], list[sp.Expr]]:
    """Return the coefficients of g0(X) and g1(X) (step 3-4) in terms of alpha, beta, c."""
    delta_on_circle = c1**2 + c2**2 + 1 + 2 * c1 * X + 2 * c2 * Y
    g = sp.Poly(sp.expand(eq32_form(ALPHA, BETA, c1 + X, c2 + Y, delta_on_circle)), Y)
    g0 = sp.Integer(0)
    g1 = sp.Integer(0)
    for (k,), coeff in g.terms():
        # Y^k = Y^(k mod 2) (1 - X^2)^(k div 2) on the circle.
        if k % 2 == 0:
            g0 += coeff * (1 - X**2) ** (k // 2)
        else:
            g1 += coeff * (1 - X**2) ** (k // 2)
    p0 = sp.Poly(sp.expand(g0), X)
    p1 = sp.Poly(sp.expand(g1), X)
    assert p0.degree() <= 5 and p1.degree() <= 4
    return (
        [p0.coeff_monomial(X**i) for i in range(6)],
        [p1.coeff_monomial(X**i) for i in range(5)],
    )


def sylvester_gammas() -> list[sp.Expr]:
    """Return gamma_0..gamma_10 of eq. (33) as polynomials in the g0/g1 coefficients."""
    g0 = sum(G0[i] * X**i for i in range(6))
    g1 = sum(G1[i] * X**i for i in range(5))
    # Sylvester matrix of p = g1 Y + g0 (degree 1) and q = Y^2 + (X^2 - 1) (degree 2) in Y.
    syl = sp.Matrix([[g1, g0, 0], [0, g1, g0], [1, 0, X**2 - 1]])
    res = sp.Poly(sp.expand(syl.det()), X)
    assert res.degree() == 10
    return [res.coeff_monomial(X**j) for j in range(11)]


def verify_resultant(
    ab: list[sp.Expr], g0c: list[sp.Expr], g1c: list[sp.Expr], gam: list[sp.Expr], f1: sp.Poly
) -> None:
    """Check f3 against sympy.resultant(f1, f2, y) of the unreduced eq. (30), (32)."""
    rng = random.Random(20240601)
    for _ in range(2):
        vals = {
            l1: sp.Rational(rng.randint(2, 30), rng.randint(1, 7)),
            l2: sp.Rational(rng.randint(2, 30), rng.randint(1, 7)),
            a: sp.Rational(rng.randint(1, 30), rng.randint(1, 7)),
            b: sp.Rational(rng.randint(1, 30), rng.randint(1, 7)),
            c1: sp.Rational(rng.randint(-30, 30), rng.randint(1, 7)),
            c2: sp.Rational(rng.randint(-30, 30), rng.randint(1, 7)),
        }
        f2 = (x - c1) ** 2 + (y - c2) ** 2 - 1  # eq. (30) with r = 1
        full = sp.resultant(f1.as_expr().subs(vals), f2.subs(vals), y)
        full = sp.Poly(sp.expand(full.subs(x, vals[c1] + X)), X)
        sub_ab = {s: e.subs(vals) for s, e in zip(list(ALPHA) + list(BETA), ab, strict=True)}
        sub_ab[c1], sub_ab[c2] = vals[c1], vals[c2]
        sub_g = {s: e.subs(sub_ab) for s, e in zip(G0 + G1, g0c + g1c, strict=True)}
        mine = sp.Poly(sum(gam[j].subs(sub_g) * X**j for j in range(11)), X)
        assert full.degree() == 10 and mine.degree() == 10
        ratio = full.LC() / mine.LC()
        assert sp.expand(full.as_expr() - ratio * mine.as_expr()) == 0, "resultant mismatch"


class _Program:
    """A straight-line program: named temporaries, each a small expression of earlier ones."""

    def __init__(self, prefix: str) -> None:
        self.prefix = prefix
        self.defs: list[tuple[sp.Symbol, sp.Expr]] = []

    def name(self, expr: sp.Expr, force: bool = False) -> sp.Expr:
        """Return ``expr`` itself if atomic (or ``number * symbol``), else a new temporary."""
        expr = sp.expand(expr)
        simple = expr.is_Mul and len(expr.args) == 2 and expr.args[0].is_Number
        if expr.is_Atom or (simple and not force):
            return expr
        sym = sp.Symbol(f"{self.prefix}{len(self.defs)}")
        self.defs.append((sym, expr))
        return sym

    def inline(self, expr: sp.Expr) -> sp.Expr:
        """Return ``expr`` with every temporary replaced by its definition (for checks)."""
        for sym, val in reversed(self.defs):
            expr = expr.xreplace({sym: val})
        return sp.expand(expr)


class _CirclePoly:
    """``p0(X) + p1(X) Y`` on the unit circle ``X^2 + Y^2 = 1`` (coefficients lowest first)."""

    def __init__(self, p0: list, p1: list) -> None:
        self.p0 = [sp.sympify(v) for v in p0]
        self.p1 = [sp.sympify(v) for v in p1]

    @staticmethod
    def _conv(u: list, v: list) -> list:
        out = [sp.Integer(0)] * (len(u) + len(v) - 1) if u and v else []
        for i, ui in enumerate(u):
            for j, vj in enumerate(v):
                out[i + j] += ui * vj
        return out

    @staticmethod
    def _add(u: list, v: list) -> list:
        n = max(len(u), len(v))
        return [(u[i] if i < len(u) else 0) + (v[i] if i < len(v) else 0) for i in range(n)]

    def __add__(self, other: _CirclePoly) -> _CirclePoly:
        return _CirclePoly(self._add(self.p0, other.p0), self._add(self.p1, other.p1))

    def __mul__(self, other: _CirclePoly) -> _CirclePoly:
        # (a0 + a1 Y)(b0 + b1 Y) = a0 b0 + a1 b1 (1 - X^2) + (a0 b1 + a1 b0) Y.
        q = self._conv(self.p1, other.p1)
        return _CirclePoly(
            self._add(self._add(self._conv(self.p0, other.p0), q), [0, 0] + [-v for v in q]),
            self._add(self._conv(self.p0, other.p1), self._conv(self.p1, other.p0)),
        )

    def named(self, prog: _Program) -> _CirclePoly:
        """Return the same polynomial with every coefficient bound to a temporary."""
        return _CirclePoly([prog.name(v) for v in self.p0], [prog.name(v) for v in self.p1])

    def trimmed(self) -> _CirclePoly:
        """Return the polynomial without trailing zero coefficients."""

        def trim(u: list) -> list:
            u = [sp.expand(v) for v in u]
            while u and u[-1] == 0:
                u.pop()
            return u

        return _CirclePoly(trim(self.p0), trim(self.p1))


def circle_reduction_program() -> tuple[_Program, list[sp.Expr], list[sp.Expr]]:
    """Return a cheap straight-line program for g0, g1 (step 3-4): eq. (32) in Horner form.

    ``f1 = (((b3 Delta + a8 x + a7 y + b2) x y) Delta + cubic + b1 x y) Delta
    + (a2 x + a1 y) x y`` with ``cubic = x^2 (a6 x + a5 y) + y^2 (a4 x + a3 y)``,
    multiplied out in the ``p0(X) + p1(X) Y`` representation (``Y^2 = 1 - X^2``).
    """
    a1_, a2_, a3_, a4_, a5_, a6_, a7_, a8_ = ALPHA
    b1_, b2_, b3_ = BETA
    prog = _Program("u")
    xp = _CirclePoly([c1, 1], [])
    yp = _CirclePoly([c2], [1])
    delta = _CirclePoly(
        [prog.name(c1**2 + c2**2 + 1), prog.name(2 * c1, force=True)],
        [prog.name(2 * c2, force=True)],
    )
    xy = (xp * yp).named(prog)
    x2 = (xp * xp).named(prog)
    y2 = (yp * yp).named(prog)

    def lin(p: sp.Expr, q: sp.Expr, r0: sp.Expr = 0) -> _CirclePoly:
        """Return ``p x + q y + r0``."""
        return _CirclePoly([p * c1 + q * c2 + r0, p], [q]).named(prog)

    inner = (_CirclePoly([b3_ * delta.p0[0], b3_ * delta.p0[1]], [b3_ * delta.p1[0]])).named(prog)
    inner = (inner + lin(a8_, a7_, b2_)).named(prog)
    acc = (inner * xy).named(prog)
    acc = (acc * delta).named(prog)
    cubic = (x2 * lin(a6_, a5_)).named(prog) + (y2 * lin(a4_, a3_)).named(prog)
    b1xy = _CirclePoly([b1_ * v for v in xy.p0], [b1_ * v for v in xy.p1])
    acc = (acc + cubic + b1xy).named(prog)
    acc = (acc * delta).named(prog)
    acc = (acc + (lin(a2_, a1_) * xy).named(prog)).trimmed().named(prog)
    return prog, acc.p0, acc.p1


class _Printer(StrPrinter):
    """Print polynomials with integer powers as products (fast for floats and arrays)."""

    def _print_Pow(self, expr: sp.Pow, rational: bool = False) -> str:
        base, exp = expr.as_base_exp()
        if exp.is_Integer and int(exp) >= 2:
            inner = self.parenthesize(base, sp.printing.precedence.PRECEDENCE["Mul"])
            return "(" + "*".join([inner] * int(exp)) + ")"
        raise ValueError(f"unexpected power {expr}")


def emit_program(
    name: str, args: list[str], outs: list[str], prog: _Program, exprs: list[sp.Expr], doc: str
) -> str:
    """Return the source of a generated function running the straight-line ``prog``."""
    pr = _Printer()
    lines = ["@kernel", f"def {name}({', '.join(args)}):", f'    """{doc}"""']
    for sym, expr in prog.defs:
        lines.append(f"    {sym} = {pr.doprint(expr)}")
    for out, expr in zip(outs, exprs, strict=True):
        lines.append(f"    {out} = {pr.doprint(expr)}")
    lines.append(f"    return ({', '.join(outs)},)")
    return "\n".join(lines) + "\n"


def emit_function(
    name: str, args: list[str], outs: list[str], exprs: list[sp.Expr], doc: str, prefix: str
) -> str:
    """Return the source of one generated function returning ``exprs`` as a tuple."""
    symbols = sp.numbered_symbols(prefix)
    reps, reduced = sp.cse(exprs, symbols=symbols, optimizations="basic", order="canonical")
    pr = _Printer()
    lines = ["@kernel", f"def {name}({', '.join(args)}):", f'    """{doc}"""']
    for sym, expr in reps:
        lines.append(f"    {sym} = {pr.doprint(expr)}")
    for out, expr in zip(outs, reduced, strict=True):
        lines.append(f"    {out} = {pr.doprint(expr)}")
    lines.append(f"    return ({', '.join(outs)},)")
    return "\n".join(lines) + "\n"


def generate() -> str:
    """Return the text of ``_coefficients.py``."""
    f0 = objective()
    P = sp.expand((x**2 + y**2) * ((l1 + l2 + a) * (x**2 + y**2) + b))
    Q = sp.expand(
        l1 * l2 * (x**2 + y**2) ** 2
        + a * b * (x**2 + y**2)
        + a * (x**2 + y**2) * (l1 * y**2 + l2 * x**2)
        + b * (l1 * x**2 + l2 * y**2)
    )
    assert sp.simplify(f0 - P / Q) == 0, "f0 != P/Q"
    f1 = f1_polynomial(f0)
    assert f1.total_degree() == 8
    ab = fit_alpha_beta(f1)
    g0c, g1c = circle_reduction()
    prog, p0, p1 = circle_reduction_program()
    assert len(p0) == 6 and len(p1) == 5
    for mine, ref in zip(p0 + p1, g0c + g1c, strict=True):
        assert sp.expand(prog.inline(mine) - ref) == 0, "circle program != expanded reduction"
    gam = sylvester_gammas()
    verify_resultant(ab, g0c, g1c, gam, f1)

    header = f'''"""GENERATED by tools/derive_polynomials.py (sympy {sp.__version__}); do not edit.

Coefficients of the Case-I polynomial system of the single-sensor problem (paper Section
IV-A): ``alpha1..8, beta1..3`` of the 8th-order stationarity polynomial f1 (eq. 32), the
coefficients of its reduction ``g0(X) + g1(X) Y`` to the (centred, unit) speed circle
(eq. 30), and ``gamma0..10`` of the 10th-order Sylvester resultant f3 (eq. 33). See the
derivation script's docstring for the variables: the prior information is diagonal
(``l1``, ``l2``), ``a = 1/sigma_d^2``, and lengths are in units of ``r`` (``b`` is
``r^-2/sigma_theta^2``, ``c1, c2`` are ``c / r``); ``X = (x - c1) / r``.

Every function uses only ``+ - *`` and is a compiled kernel (:mod:`activetrack._jit`):
arguments may be floats or numpy arrays.
"""

from activetrack._jit import kernel

# The generated body is kept exactly as printed (ruff format must not rewrap it).
# fmt: off

'''
    funcs = [
        emit_function(
            "alpha_beta",
            ["l1", "l2", "a", "b", "c1", "c2"],
            [f"alpha{i}" for i in range(1, 9)] + [f"beta{i}" for i in range(1, 4)],
            ab,
            "Return (alpha1..alpha8, beta1..beta3) of eq. (32).",
            "t",
        ),
        emit_program(
            "circle_reduction",
            [f"alpha{i}" for i in range(1, 9)] + [f"beta{i}" for i in range(1, 4)] + ["c1", "c2"],
            [f"h{i}" for i in range(6)] + [f"k{i}" for i in range(5)],
            prog,
            p0 + p1,
            "Return (h0..h5, k0..k4): f1 on the circle is sum h_i X^i + Y sum k_i X^i.",
        ),
        emit_function(
            "sylvester_gammas",
            [f"h{i}" for i in range(6)] + [f"k{i}" for i in range(5)],
            [f"gamma{j}" for j in range(11)],
            gam,
            "Return (gamma0..gamma10) of eq. (33): f3(X) = g0^2 + (X^2 - 1) g1^2.",
            "v",
        ),
    ]
    tail = '''

@kernel
def f3_coefficients(l1, l2, a, b, c1, c2):
    """Return (gamma0..gamma10) of eq. (33), lowest degree first, in the variable X."""
    return sylvester_gammas(*circle_reduction(*alpha_beta(l1, l2, a, b, c1, c2), c1, c2))


# fmt: on
'''
    return header + "\n\n".join(funcs) + tail


def main(argv: list[str] | None = None) -> int:
    """Print the generated module, or with ``--check`` compare it with the committed file."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="diff against the committed file")
    args = parser.parse_args(argv)
    text = generate()
    if not args.check:
        sys.stdout.write(text)
        return 0
    current = TARGET.read_text() if TARGET.exists() else ""
    if current == text:
        print(f"{TARGET.relative_to(ROOT)} is up to date")
        return 0
    sys.stdout.writelines(
        difflib.unified_diff(
            current.splitlines(True), text.splitlines(True), "committed", "generated"
        )
    )
    return 1


if __name__ == "__main__":
    raise SystemExit(main())
