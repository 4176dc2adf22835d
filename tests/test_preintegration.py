"""Pre-integration tables (dvr_gl.model.preintegration) and their GLSL twin.

The oracle is ``exact_segment``: nested adaptive quadrature (scipy quad) of the
definition, sharing no code with the table. The table's float64 values at the nodes
(``table64``) must match it to far below 1e-9; the float32 table adds its own rounding
(relative 2**-24)."""

import math
import time

import numpy as np
import pytest

import dvr_gl
from dvr_gl.gl import harness
from dvr_gl.gl.capabilities import linear_filter_is_exact
from dvr_gl.model.preintegration import (OPAQUE_SENTINEL, TABLE_SIZE, PreintegrationTable, build_table,
                                   exact_segment, length_correction_error, mean_extinction, opacity_support)

U32 = 2.0 ** -24
TOL_EXACT = 1e-11          # table64 vs exact_segment (measured: ~1e-14)

TF = dvr_gl.TransferFunction

# A smooth ramp.
RAMP = TF(color=[(0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0, 1.0)], opacity=[(0.0, 0.0), (1.0, 0.8)],
          unit_distance=0.01)
# A spike 0.005 wide (1/240 of the table's range below) whose colour jumps from red to blue
# at its peak, zero opacity elsewhere.
SPIKE = TF(color=[(0.0, 1, 0, 0), (0.5, 1, 0, 0), (0.5025, 0, 0, 1), (1.0, 0, 0, 1)],
           opacity=[(0.0, 0.0), (0.4975, 0.0), (0.5, 0.95), (0.5025, 0.0)], unit_distance=0.01)
# A plateau of alpha = 1 between 0.4 and 0.6, zero below 0.2, colours changing throughout.
PLATEAU = TF(color=[(0.0, 0, 1, 0), (0.3, 1, 0, 0), (0.7, 0, 0, 1), (1.0, 1, 1, 0)],
             opacity=[(0.0, 0.0), (0.2, 0.0), (0.4, 1.0), (0.6, 1.0), (0.8, 0.3)], unit_distance=0.01)
# alpha = 1 at a single value (0.5), and alpha within 1e-12 of 1 (a near-singular tau).
POINT = TF(color=[(0.0, 0, 1, 0), (0.45, 1, 0, 0), (0.7, 0, 0, 1), (1.0, 1, 1, 0)],
           opacity=[(0.0, 0.1), (0.5, 1.0), (0.9, 0.0)], unit_distance=0.01)
NEAR_ONE = TF(color=[(0.0, 0, 1, 0), (0.45, 1, 0, 0), (0.7, 0, 0, 1), (1.0, 1, 1, 0)],
              opacity=[(0.0, 0.1), (0.5, 1 - 1e-12), (0.9, 0.0)], unit_distance=0.01)
CASES = {"ramp": RAMP, "spike": SPIKE, "plateau": PLATEAU, "alpha1_point": POINT, "near_one": NEAR_ONE}
VALUE_RANGE = (-0.1, 1.1)
SMALL = 41                 # nodes of the tables checked against the oracle (cell 0.03)


def _at_nodes(table, i, j, length):
    """(C, A) from table64 at node pair (i, j), float64, no interpolation."""
    k, d = table.table64[i, j, :3], table.table64[i, j, 3]
    a = 1.0 if d >= OPAQUE_SENTINEL else -math.expm1(-length * d)
    return np.r_[k * a, a]


def _meets_alpha_one(tf, a, b):
    """Whether the closed interval between a and b holds a value with alpha = 1."""
    lo, hi = min(a, b), max(a, b)
    p = tf.opacity_points
    return bool(tf.opacity(lo) >= 1 or tf.opacity(hi) >= 1
                or np.any((p[:, 1] >= 1) & (p[:, 0] > lo) & (p[:, 0] < hi)))


def _pairs(n, rng, count):
    """Node pairs: diagonal, neighbours both ways, extremes, and random ones."""
    fixed = [(0, n - 1), (n - 1, 0), (0, 0), (n - 1, n - 1), (n // 2, n // 2 + 1), (n // 2 + 1, n // 2),
             (3, 4), (4, 3), (n // 3, 2 * n // 3), (2 * n // 3, n // 3)]
    rand = [tuple(p) for p in rng.integers(0, n, (count, 2))]
    return fixed + rand


# -- closed-form optical depth ---------------------------------------------------------

def _decimal_mean_extinction(tf, lo, hi):
    """Mean of tau over [lo, hi] inside one linear piece of alpha, in 50-digit decimals:
    with b = 1 - alpha linear, the mean of -ln b is -(B(b1) - B(b0)) / (b1 - b0), where
    B(b) = b ln b - b; -ln b itself where b1 = b0."""
    from decimal import Decimal, localcontext
    pts = tf.opacity_points
    with localcontext() as ctx:
        ctx.prec = 50

        def b_at(s):
            s = Decimal(float(s))
            if s <= Decimal(float(pts[0, 0])):
                return 1 - Decimal(float(pts[0, 1]))
            if s >= Decimal(float(pts[-1, 0])):
                return 1 - Decimal(float(pts[-1, 1]))
            k = int(np.searchsorted(pts[:, 0], float(s), side="right")) - 1
            x0, x1 = (Decimal(float(v)) for v in pts[k:k + 2, 0])
            a0, a1 = (Decimal(float(v)) for v in pts[k:k + 2, 1])
            return 1 - (a0 + (a1 - a0) * (s - x0) / (x1 - x0))

        b0, b1 = b_at(lo), b_at(hi)
        if b0 == b1:
            mean = -b0.ln()
        else:
            B = lambda b: b * b.ln() - b if b > 0 else Decimal(0)  # noqa: E731
            mean = -(B(b1) - B(b0)) / (b1 - b0)
        return float(mean / Decimal(tf.unit_distance))


@pytest.mark.parametrize("name", ["ramp", "spike", "plateau", "alpha1_point", "near_one"])
def test_mean_extinction_closed_form(name):
    from scipy import integrate
    tf = CASES[name]
    rng = np.random.default_rng(11)
    sf = np.r_[rng.uniform(-0.2, 1.2, 40), 0.3, 0.3, 0.5, 0.2, 0.49999, 0.7]
    sb = np.r_[rng.uniform(-0.2, 1.2, 40), 0.3, 0.3 + 1e-12, 0.5 - 1e-13, 0.2 + 1e-9, 0.50001, 0.1]
    D = mean_extinction(tf, sf, sb)
    np.testing.assert_array_equal(D, mean_extinction(tf, sb, sf))   # symmetric
    for a, b, d in zip(sf, sb, D):
        lo, hi = min(a, b), max(a, b)
        if _meets_alpha_one(tf, lo, hi):
            assert d == np.inf
            continue
        if not np.any((tf.opacity_points[:, 0] > lo) & (tf.opacity_points[:, 0] < hi)):
            # one linear piece of alpha: the antiderivative of -ln b in 50-digit decimals
            # (no cancellation there, however short the interval)
            ref = _decimal_mean_extinction(tf, lo, hi)
            assert abs(d - ref) <= 1e-13 * (1 + ref), (a, b, d, ref)
            continue
        # quad between knots, and on pieces 2^-m of the way to a knot where alpha nears 1
        # (so that the near-logarithmic peak of tau is resolved by the partition)
        cuts = {lo, hi}
        for k in tf.knots:
            if tf.opacity(k) > 0.5:
                cuts.update(k + sgn * 0.5 ** m for m in range(4, 31) for sgn in (-1, 1))
            cuts.add(k)
        cuts = sorted(c for c in cuts if lo <= c <= hi)
        ref = sum(integrate.quad(lambda s: float(tf.extinction(s)), c0, c1, epsabs=1e-14, epsrel=1e-12,
                                 limit=200)[0] for c0, c1 in zip(cuts[:-1], cuts[1:])) / (hi - lo)
        assert abs(d - ref) <= 1e-10 * (1 + ref), (a, b, d, ref)
    # equal ends: exactly tau there
    s = np.array([0.0, 0.25, 0.5, 0.95])
    np.testing.assert_allclose(mean_extinction(tf, s, s), tf.extinction(s), rtol=1e-15)


# -- the table against the oracle --------------------------------------------------------

@pytest.mark.parametrize("name", ["ramp", "spike", "plateau", "alpha1_point", "near_one"])
@pytest.mark.parametrize("length_over_unit", [0.5, 20.0])
def test_table_nodes_match_exact_segment(name, length_over_unit):
    tf = CASES[name]
    length = length_over_unit * tf.unit_distance
    table = build_table(tf, VALUE_RANGE, length, SMALL)
    s = table.nodes
    rng = np.random.default_rng(7)
    worst_c = worst_k = 0.0
    for i, j in _pairs(SMALL, rng, 14):
        ref = exact_segment(tf, s[i], s[j], length)
        got = _at_nodes(table, i, j, length)
        worst_c = max(worst_c, np.abs(got - ref).max())
        if ref[3] > 1e-6:
            worst_k = max(worst_k, np.abs(table.table64[i, j, :3] - ref[:3] / ref[3]).max())
        opaque = _meets_alpha_one(tf, s[i], s[j])
        assert (table.table[i, j, 3] == np.float32(OPAQUE_SENTINEL)) == opaque
        if opaque:
            assert ref[3] == 1.0 and got[3] == 1.0
    assert worst_c <= TOL_EXACT
    assert worst_k <= 1e-9
    # the float32 table is the float64 one rounded (subnormals to their absolute spacing)
    np.testing.assert_allclose(table.table, table.table64, rtol=U32, atol=np.finfo(np.float32).smallest_subnormal)


def test_table_special_segments():
    """Crossing the spike both ways, ending on and starting at alpha = 1, inside a
    plateau, and inside a region of zero opacity: exact at the nodes."""
    L = 0.02
    for tf, pairs in ((SPIKE, [(0.4975, 0.5025), (0.5025, 0.4975), (0.5, 0.5), (0.498, 0.502), (0.502, 0.498)]),
                      (PLATEAU, [(0.1, 0.4), (0.4, 0.1), (0.5, 0.55), (0.7, 0.5), (0.0, 0.15), (0.1, 0.9)]),
                      (POINT, [(0.3, 0.5), (0.5, 0.8), (0.8, 0.5), (0.2, 0.7)])):
        # nodes every 0.005 (the spike's: every 0.0005) over the values with opacity
        # (all of them for a TF that reaches alpha = 1): every value above is a node
        lo, hi = opacity_support(tf, *VALUE_RANGE)
        table = build_table(tf, VALUE_RANGE, L, int(round((hi - lo) / (0.0005 if tf is SPIKE else 0.005))) + 1)
        assert (table.lo, table.hi) == ((0.4975, 0.5025) if tf is SPIKE else (-0.1, 1.1))
        for a, b in pairs:
            i, j = (int(round((v - table.lo) * table.scale)) for v in (a, b))
            ref = exact_segment(tf, table.nodes[i], table.nodes[j], L)
            np.testing.assert_allclose(_at_nodes(table, i, j, L), ref, rtol=0, atol=TOL_EXACT)
    # zero opacity over the whole segment: nothing at all
    table = build_table(PLATEAU, VALUE_RANGE, L, 241)
    i, j = (int(round((v - table.lo) * table.scale)) for v in (0.0, 0.15))
    assert table.table64[i, j, 3] == 0 and np.all(np.isfinite(table.table64[..., :3]))
    np.testing.assert_array_equal(table.segment(table.nodes[i], table.nodes[j], L), 0.0)


def test_segments_reaching_beyond_the_values_with_opacity():
    """The spike's table spans the spike alone; a segment from outside it into it (or
    across it) is empty outside and counts with its share of the length within, its
    colour moved towards K0 by the length correction. Against the definition: within
    2e-3, and at most 0.15x the error of K at the nominal length (measured 0.03x to
    0.13x); segments entirely outside are exactly zero."""
    L = 0.02
    table = build_table(SPIKE, VALUE_RANGE, L, 81)
    for a, b in [(0.49, 0.52), (0.52, 0.49), (0.495, 0.505), (0.505, 0.495), (0.3, 0.5), (0.5, 0.9)]:
        ref = exact_segment(SPIKE, a, b, L)
        got = table.segment(a, b, L)
        share = table.inside_fraction(a, b)
        uncorrected = table.interpolate(a, b)[:3] * got[3]
        assert share < 1
        np.testing.assert_allclose(got[3], ref[3], rtol=4 * U32, atol=1e-12)     # D: float32 at the nodes
        assert np.abs(got - ref).max() <= 2e-3, (a, b, got, ref)
        assert np.abs(got - ref).max() <= 0.15 * np.abs(uncorrected - ref[:3]).max() + 1e-9, (a, b)
    np.testing.assert_array_equal(table.segment(0.1, 0.3, L), 0.0)
    np.testing.assert_array_equal(table.segment(0.6, 0.9, L), 0.0)


def test_values_beyond_an_uncut_end_take_the_end_value():
    """A TF with opacity at its ends keeps the table over the data and knots, not cut:
    values rounded just past an end (a plateau at the data's maximum) read the end's
    entry, as before; a cut end (the spike's) makes them empty."""
    edge = TF(color=[(0.0, 1, 0, 0), (1.0, 0, 0, 1)], opacity=[(0.0, 0.3), (1.0, 0.5)], unit_distance=0.01)
    table = build_table(edge, (0.0, 1.0), 0.01, 64)
    assert table.cut == (False, False)
    for end in (0.0, 1.0):
        beyond = np.nextafter(end, -1.0 if end == 0.0 else 2.0)
        np.testing.assert_array_equal(table.segment(beyond, beyond, 0.01), table.segment(end, end, 0.01))
        assert table.segment(end, end, 0.01)[3] > 0
    spike = build_table(SPIKE, VALUE_RANGE, 0.01, 64)
    assert spike.cut == (True, True)
    np.testing.assert_array_equal(spike.segment(np.nextafter(spike.lo, 0.0), np.nextafter(spike.lo, 0.0), 0.01), 0.0)


def test_length_correction_errs_far_less_than_the_nominal_colour():
    """``K0 + (K(L0) - K0) w`` against the exact colour at other lengths (tables made for
    those lengths, exact at the nodes), over all pairs of nodes: the uncorrected K(L0)
    errs 20x to 1000x more on a ramp and a spike (measured by length_correction_error)."""
    for tf in (RAMP, SPIKE):
        plain = length_correction_error(tf, (0.0, 1.0), tf.unit_distance, (0.1, 0.5, 1.5), size=65, corrected=False)
        corrected = length_correction_error(tf, (0.0, 1.0), tf.unit_distance, (0.1, 0.5, 1.5), size=65)
        for r in plain:
            assert corrected[r] <= plain[r] / 5, (tf, r, corrected[r], plain[r])


def test_constant_segments_match_the_per_sample_formula():
    """s_front == s_back: alpha_L = 1 - (1 - alpha)^(L/u), colour c alpha_L (contract,
    section 4); exact at the nodes (float32 rounding aside), O(h^2) between them."""
    L = 0.3 * RAMP.unit_distance
    table = build_table(RAMP, (0.0, 1.0), L, 256)
    for s, tol in ((table.nodes, 4 * U32), (np.linspace(0.0, 1.0, 1001), 1e-5)):
        alpha = RAMP.opacity(s)
        a_l = 1 - (1 - alpha) ** (L / RAMP.unit_distance)
        ref = np.c_[RAMP.color(s) * a_l[:, None], a_l]
        np.testing.assert_allclose(table.segment(s, s, L), ref, rtol=0, atol=tol)
    # and at other lengths, the same formula (the colour of a constant segment is c)
    for r in (0.1, 2.5):
        s = table.nodes
        a_l = 1 - (1 - RAMP.opacity(s)) ** (r * L / RAMP.unit_distance)
        np.testing.assert_allclose(table.segment(s, s, r * L),
                                   np.c_[RAMP.color(s) * a_l[:, None], a_l], rtol=0, atol=4 * U32)


@pytest.mark.parametrize("name", ["ramp", "spike", "plateau"])
def test_opacity_is_exact_at_every_length(name):
    """D does not depend on the length: a table built for L0 gives A(L) exactly (up to
    float32 D: |dA| <= T * L * D * 2^-24 <= 2^-24 / e)."""
    tf = CASES[name]
    L0 = 0.5 * tf.unit_distance
    table = build_table(tf, VALUE_RANGE, L0, SMALL)
    s = table.nodes
    rng = np.random.default_rng(3)
    for ratio in (0.1, 0.7, 1.0, 1.6, 4.0):
        for i, j in _pairs(SMALL, rng, 4):
            ref = exact_segment(tf, s[i], s[j], ratio * L0)
            got = table.segment(s[i], s[j], ratio * L0)
            assert abs(got[3] - ref[3]) <= U32, (ratio, i, j, got, ref)
            if ratio == 1.0:
                np.testing.assert_allclose(got, ref, rtol=0, atol=4 * U32)


def test_length_correction_error_is_reported_and_shrinks_towards_ratio_one():
    ratios = (0.1, 0.5, 0.9, 1.0, 1.1, 1.5, 2.0)
    smooth = TF(color=RAMP.color_points, opacity=RAMP.opacity_points, unit_distance=1.0)
    spike = TF(color=SPIKE.color_points, opacity=SPIKE.opacity_points, unit_distance=1.0)
    for name, tf in (("smooth ramp", smooth), ("narrow spike", spike)):
        err = length_correction_error(tf, (0.0, 1.0), 1.0, ratios, size=256)
        print(f"\nlength-correction error, {name}, L0 = unit distance: "
              + ", ".join(f"L/L0={r:g}: {e:.2e}" for r, e in err.items()))
        assert err[1.0] <= 1e-15
        assert err[0.9] < err[0.5] and err[1.1] < err[1.5] < err[2.0]
        assert 0 < err[1.1] < 0.05 and err[2.0] < 0.2
        # the reported figure bounds spot checks against the oracle
        table = build_table(tf, (0.0, 1.0), 1.0, 256)
        for i, j in ((0, 255), (120, 140), (140, 120), (128, 129)):
            for r in (0.5, 2.0):
                ref = exact_segment(tf, table.nodes[i], table.nodes[j], r)
                got = table.segment(table.nodes[i], table.nodes[j], r)
                assert np.abs(got[:3] - ref[:3]).max() <= err[r] + 1e-6


def test_build_time_of_the_default_table():
    """Reported, not asserted (the bound in the module docstring: about a second for the
    default 512 on two cores)."""
    tf = TF(color=[(0, 0, 0, 1), (0.3, 1, 0, 0), (0.5, 1, 1, 0), (1, 1, 1, 1)],
            opacity=[(0, 0), (0.3, 0.2), (0.31, 0.99), (0.32, 0.1), (0.8, 0.9), (1, 0)], unit_distance=0.02)
    t0 = time.perf_counter()
    table = build_table(tf, (0.0, 1.0), 0.01)
    dt = time.perf_counter() - t0
    print(f"\nbuild_table, size {TABLE_SIZE}: {dt:.2f} s")
    assert table.size == TABLE_SIZE and table.table.shape == (TABLE_SIZE, TABLE_SIZE, 4)
    assert table.table.dtype == np.float32 and np.all(np.isfinite(table.table))


# -- layout, ranges, input checks ------------------------------------------------------------

def test_range_covers_the_values_with_opacity_and_layout():
    """The nodes span the values with opacity within the data and the knots: all of the
    data for a TF opaque at its last knot, just the spike for a spike."""
    table = build_table(RAMP, (0.2, 3.0), 0.01, 9)
    assert (table.lo, table.hi) == (0.0, 3.0)          # transparent below 0, opaque to the data's end
    np.testing.assert_allclose(table.scale, 8 / 3.0)
    np.testing.assert_allclose(table.nodes, np.linspace(0.0, 3.0, 9))
    assert build_table(RAMP, (-5.0, 0.5), 0.01, 9).lo == 0.0
    spike = build_table(SPIKE, (-5.0, 3.0), 0.01, 9)
    assert (spike.lo, spike.hi) == (0.4975, 0.5025)
    raw = np.frombuffer(table.texture_bytes(), np.float32).reshape(18, 9, 4)
    np.testing.assert_array_equal(raw[:9], table.table)   # row (y) = front node, x = back node
    np.testing.assert_array_equal(raw[9:, :, :3], table.colour0)   # then the zero-length colour
    np.testing.assert_array_equal(raw[9:, :, 3], 0.0)
    # no opacity anywhere: the data and knots, as before
    clear = TF(color=[(0.0, 1, 0, 0), (1.0, 0, 1, 0)], opacity=[(0.0, 0.0), (1.0, 0.0)])
    assert (build_table(clear, (0.2, 3.0), 1.0, 4).lo, build_table(clear, (0.2, 3.0), 1.0, 4).hi) == (0.0, 3.0)
    # a single value and a single knot: the table still spans a unit interval
    one = TF(color=[(2.0, 1, 0, 0)], opacity=[(2.0, 0.5)])
    t1 = build_table(one, (2.0, 2.0), 1.0, 4)
    assert t1.hi > t1.lo and np.isfinite(t1.scale)
    np.testing.assert_allclose(t1.segment(2.0, 2.0, 1.0), [0.5, 0, 0, 0.5], atol=1e-7)
    # beyond the table's values a segment is empty: only its part within counts
    np.testing.assert_allclose(spike.segment(-10.0, 99.0, 0.02),
                               spike.segment(spike.lo, spike.hi, 0.02 * 0.005 / 109.0), rtol=1e-12, atol=0)
    np.testing.assert_array_equal(spike.segment(0.6, 0.9, 0.02), 0.0)


@pytest.mark.parametrize("kwargs, match", [
    (dict(length=0.0), r"length must be a positive finite number, got 0\.0"),
    (dict(length=-1.0), r"length .* got -1\.0"),
    (dict(length=float("nan")), r"length .* got nan"),
    (dict(length=float("inf")), r"length .* got inf"),
    (dict(size=1), r"size must be an integer >= 2, got 1"),
    (dict(size=2.5), r"size .* got 2\.5"),
    (dict(value_range=(0.0, float("nan"))), r"value_range must be finite, got \(0\.0, nan\)"),
    (dict(value_range=(float("-inf"), 1.0)), r"value_range must be finite, got \(-inf, 1\.0\)"),
    (dict(value_range=(1.0, 0.0)), r"value_range must be \(low, high\) with low <= high, got \(1\.0, 0\.0\)"),
    (dict(value_range=(1.0,)), r"value_range must be two numbers"),
])
def test_bad_input_raises(kwargs, match):
    args = dict(tf=RAMP, value_range=(0.0, 1.0), length=0.1, size=16)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        build_table(**args)


def test_bad_input_raises_elsewhere():
    with pytest.raises(ValueError, match=r"length .* got 0"):
        exact_segment(RAMP, 0.1, 0.2, 0)
    with pytest.raises(ValueError, match=r"ratio .* got -1"):
        length_correction_error(RAMP, (0.0, 1.0), 0.1, [-1], size=8)
    table = build_table(RAMP, (0.0, 1.0), 0.1, 8)
    with pytest.raises(ValueError, match="length must be finite and >= 0"):
        table.segment(0.1, 0.2, -1.0)
    with pytest.raises(TypeError, match="tf must be a dvr_gl.TransferFunction"):
        build_table("ramp", (0.0, 1.0), 0.1)
    assert isinstance(table, PreintegrationTable)


# -- preintegration.glsl ------------------------------------------------------------------

def test_program_cache_sets_the_filter_switch_from_the_probe(renderer):
    # every program that declares TEXTURE_FILTER_EXACT gets the probe's answer (those
    # that do not, the other techniques' throughout the suite, build without it)
    exact = linear_filter_is_exact(renderer.ctx)
    assert renderer.programs.context_defines["TEXTURE_FILTER_EXACT"] == int(exact)
    volume = dvr_gl.Volume(np.linspace(0.0, 1.0, 6 ** 3, dtype=np.float32).reshape(6, 6, 6))
    scene = dvr_gl.Scene(volume, RAMP, dvr_gl.default_camera(volume, azimuth=30, elevation=20), 12, 12)
    renderer.render(scene, preintegrate=True)
    sources = [fs for (v, f, *_), (vs, fs, *_) in renderer.programs.sources.items() if f == "raycast/raycast.frag"]
    assert sources and all(f"#define TEXTURE_FILTER_EXACT {int(exact)}" in fs for fs in sources)


def test_both_ways_of_reading_the_table_give_the_same_image():
    """The shader's own bilinear interpolation (what GPUs with quantised filter weights
    run) and the texture unit's (llvmpipe) render the same pre-integrated and refined
    images, to float rounding: the whole ray caster, not only the segment function."""
    volume = dvr_gl.Volume(np.linspace(0.0, 1.0, 9 ** 3, dtype=np.float32).reshape(9, 9, 9) ** 2)
    tf = TF(color=[(0.0, 0.2, 0.4, 1.0), (0.5, 1.0, 0.5, 0.2), (1.0, 1.0, 1.0, 1.0)],
            opacity=[(0.0, 0.0), (0.3, 0.0), (0.35, 0.9), (0.4, 0.0), (0.8, 0.5), (1.0, 0.7)], unit_distance=1.0)
    scene = dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume, azimuth=30, elevation=20), 24, 20)
    with dvr_gl.Renderer() as r:
        exact_here = r.programs.context_defines["TEXTURE_FILTER_EXACT"]
        default = [r.render(scene, step=0.6, preintegrate=True, refine=k) for k in (1, 4)]
    images = {}
    for texture_filter in ((0, 1) if exact_here else (0,)):
        with dvr_gl.Renderer() as r:
            r.programs._context_defines = {"TEXTURE_FILTER_EXACT": texture_filter}
            images[texture_filter] = [r.render(scene, step=0.6, preintegrate=True, refine=k) for k in (1, 4)]
    # a renderer reads the way its context's probe chose
    assert all(np.array_equal(a, b) for a, b in zip(default, images[exact_here]))
    if not exact_here:   # quantised filter weights (GPUs): the texture unit is never used
        return
    for shader, unit in zip(images[0], images[1]):
        assert shader[..., 3].max() > 0.2
        # per segment the two differ by rounding (the segment test above bounds it), here
        # a few 1e-7 carried through at most 30 segments and parts: 1e-5 is that, with room
        assert np.abs(shader - unit).max() <= 1e-5


@pytest.mark.parametrize("texture_filter", [0, 1])
def test_preintegrated_segment_matches_numpy_twin(ctx, texture_filter):
    # both ways of interpolating the table: in the shader, and (where the context's
    # filter weights are exact, as the program cache sets it) by the texture unit
    if texture_filter and not linear_filter_is_exact(ctx):
        pytest.skip("this context's filter weights are quantised; the cache never sets the switch here")
    # value range offset from 0 (so lo's float32 rounding counts), an alpha = 1 plateau
    # (sentinel D), a narrow spike, zero-opacity stretches, colours changing everywhere
    tf = TF(color=[(-200.0, 0, 0, 1), (300.0, 1, 0, 0), (310.0, 0, 1, 0), (900.0, 1, 1, 1)],
            opacity=[(-200.0, 0.0), (100.0, 0.0), (300.0, 0.6), (305.0, 0.97), (310.0, 0.2),
                     (600.0, 1.0), (700.0, 1.0), (800.0, 0.0)], unit_distance=2.0)
    table = build_table(tf, (-300.0, 1000.0), 1.0, 96)
    assert np.any(table.table[..., 3] == np.float32(OPAQUE_SENTINEL))
    rng = np.random.default_rng(8)
    n = 3000
    sf = rng.uniform(-400.0, 1100.0, n)
    sb = np.where(rng.random(n) < 0.3, sf + rng.normal(0.0, 20.0, n), rng.uniform(-400.0, 1100.0, n))
    length = rng.choice([0.0, 1e-3, 0.3, 1.0, 2.5, 40.0, 1e12], n)
    sf[:6] = [-1e6, 1e6, -300.0, 1000.0, -1e6, 650.0]      # clamped ends, exact ends, plateau
    sb[:6] = [1e6, -1e6, 1000.0, -300.0, -1e6, 650.0]
    nodes = table.nodes.astype(np.float32)
    sf[6:26] = nodes[rng.integers(0, 96, 20)]                # exactly on (float32) nodes
    sb[6:26] = nodes[rng.integers(0, 96, 20)]
    inp = np.c_[sf, sb, length, np.zeros(n)].astype(np.float32)
    with ctx:
        tex = ctx.texture((table.size, 2 * table.size), 4, table.texture_bytes(), dtype="f4")
        tex.filter = (ctx.LINEAR, ctx.LINEAR)
        tex.repeat_x = tex.repeat_y = False
    try:
        gl = harness.evaluate(ctx, ["common/preintegration.glsl"],
                              "out0 = preintegratedSegment(in0.x, in0.y, in0.z);", [inp],
                              textures={"t_preint": tex}, uniforms=table.uniforms(),
                              defines={"TEXTURE_FILTER_EXACT": texture_filter}).astype(np.float64)
    finally:
        with ctx:
            tex.release()
    x = inp.astype(np.float64)
    ref = table.segment(x[:, 0], x[:, 1], x[:, 2])

    # Tolerance. The shader's table index u = (s - lo) * scale has, in float32, absolute
    # error <= U32 * (|s - lo| * scale + |lo| * scale + 2 |u|) <= U32 * (3 (size - 1) +
    # |lo| scale) for s in range (clamped values are exact at the ends). Bilinear
    # interpolation is continuous, so an index error du moves each channel by at most du
    # times its spread over the surrounding nodes (both indices: twice), plus the
    # rounding of the interpolation itself (<= 6 U32 |value|). Then A = 1 - exp(-L D):
    # |dA| <= L |dD| + 2 U32 (the product, expm1Accurate, llvmpipe's exp: a few U32),
    # and C = K A: |dC| <= |dK| A + |K| |dA| + U32.
    du = U32 * (3 * (table.size - 1) + abs(table.lo) * table.scale)
    if texture_filter:
        # the texture unit's coordinate: (u + 0.5) / height rounded, times height, less 0.5,
        # each rounded (the K0 rows sit up to 2 size down): <= 3 U32 (2 size) more
        du += 6 * U32 * table.size
    t = table.table.astype(np.float64)

    def spread(s):
        u = np.clip((s - table.lo) * table.scale, 0, table.size - 1)
        i = np.clip(np.floor(u).astype(int), 0, table.size - 2)
        idx = np.clip(i[:, None] + np.arange(-1, 3)[None, :], 0, table.size - 1)
        return idx

    fi, bi = spread(x[:, 0]), spread(x[:, 1])
    block = t[fi[:, :, None], bi[:, None, :]]                       # (n, 4, 4, 4)
    spr = block.max(axis=(1, 2)) - block.min(axis=(1, 2))
    mag = np.abs(block).max(axis=(1, 2))
    dv = 2 * du * spr + 6 * U32 * mag                                # per channel K, D
    interp = table.interpolate(x[:, 0], x[:, 1])
    with np.errstate(over="ignore", invalid="ignore"):
        tol_a = np.minimum(x[:, 2] * dv[:, 3], 1.0) + 16 * U32
        tol_c = dv[:, :3] * ref[:, 3:4] + np.abs(interp[:, :3]) * tol_a[:, None] + 2 * U32
    err = np.abs(gl - ref)
    assert np.all(err[:, 3] <= tol_a), np.max(err[:, 3] - tol_a)
    assert np.all(err[:, :3] <= tol_c), np.max(err[:, :3] - tol_c)
    # where the bound above is vacuous: opaque segments (sentinel weight >= 1e-3 of it)
    # must be exactly opaque, and zero length exactly nothing
    opaque = (interp[:, 3] >= 1e-3 * OPAQUE_SENTINEL) & (x[:, 2] > 0)
    assert opaque.sum() > 50
    assert np.all(gl[opaque, 3] == 1.0) and np.all(ref[opaque, 3] == 1.0)
    np.testing.assert_allclose(gl[opaque, :3], ref[opaque, :3], rtol=0, atol=1e-4)
    assert np.all(gl[x[:, 2] == 0] == 0)
    # the clamped ends equal the table's corner entries
    np.testing.assert_allclose(gl[:4], ref[:4], rtol=0, atol=8 * U32)
    # a visible spread of results (the test is not all zeros and ones)
    assert np.sum((ref[:, 3] > 0.05) & (ref[:, 3] < 0.95)) > 300
