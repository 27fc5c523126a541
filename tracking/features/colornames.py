"""Color Names: RGB to 11 linguistic colour probabilities, and their 10-dim normalisation.

Thesis §3.1.1: every RGB value is mapped to the probabilities of the eleven basic colour terms of
Berlin and Kay (black, blue, brown, grey, green, orange, pink, purple, red, white, yellow). The
mapping is a lookup table over 32 x 32 x 32 = 32768 uniformly sampled RGB bins. Thesis §3.2.1: the
probabilities sum to one, so they lie in a 10-dim hyperplane orthogonal to ``(1, ..., 1)``;
expressing them in an orthonormal basis of that hyperplane centres them (the constant direction is
dropped) and the normalised table maps RGB straight to 10 values. Trackers with inner-product and
L2 kernels are invariant to the choice of that basis (thesis §4.2.2).

Two sources give the same ``(32768, 11)`` table:

* the ``w2c.mat`` table of van de Weijer, Schmid, Verbeek, Larlus, "Learning Color Names for
  Real-World Applications", IEEE TIP 18(7), 2009 — the mapping used in the thesis — read from a
  path the caller configures (:meth:`ColorNameTable.from_w2c`);
* the parametric TSE colour-naming model of Benavente, Vanrell, Baldrich, "Parametric fuzzy sets
  for automatic color naming", JOSA A 25(10), 2008 (:func:`tse_color_names`), whose published
  parameters are embedded below, evaluated at the bin centres. It is the fallback when no table
  path is configured; nothing is ever downloaded.

Row index of an 8-bit RGB pixel: ``r // 8 + 32 * (g // 8) + 1024 * (b // 8)``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from functools import cached_property
from pathlib import Path
from types import MappingProxyType
from typing import Literal, NamedTuple, get_args

import numpy as np

from tracking.features.colorspaces import require_rgb
from tracking.matfiles import read_mat

__all__ = [
    "COLOR_NAMES",
    "N_COLOR_BINS",
    "ColorNameTable",
    "ColorNamesError",
    "TseParameterSet",
    "load_w2c_table",
    "tse_color_names",
    "zero_sum_basis",
]

COLOR_NAMES: tuple[str, ...] = (
    "black",
    "blue",
    "brown",
    "grey",
    "green",
    "orange",
    "pink",
    "purple",
    "red",
    "white",
    "yellow",
)
"""Column order of every colour-name table (the order of ``w2c.mat``)."""

N_COLOR_BINS = 32 * 32 * 32
"""Rows of a colour-name table: 32 bins of width 8 per RGB channel."""

_ROW_SUM_TOLERANCE = 1e-4  # float32-saved tables are ~1e-7 off; anything larger is not a pmf

TseParameterSet = Literal["benavente2008", "parraga2009"]
"""Which published TSE fit to use (see :func:`tse_color_names`)."""


class ColorNamesError(ValueError):
    """A colour-name table could not be loaded or is not a valid ``(32768, 11)`` table."""


# --------------------------------------------------------------------------------------------
# TSE model parameters (Benavente, Vanrell, Baldrich, JOSA A 25(10), 2008; re-fit of Parraga,
# Benavente, Vanrell, Baldrich, J. Imaging Sci. Technol. 53(3), 2009, Tables I and II).
# Published figures, copied as constants so runtime code never reads a data file.
# --------------------------------------------------------------------------------------------


class _TseCategory(NamedTuple):
    """One chromatic category at one lightness level: the two sigmoid orientations (radians)
    and slopes of the triple sigmoid."""

    name: str
    alpha_x: float
    alpha_y: float
    beta_x: float
    beta_y: float


class _TseLevel(NamedTuple):
    """One lightness level: the shared elliptical centre (t = (tx, ty) in a*b* units, semi-axes
    ex, ey, rotation phi in radians, slope beta_e) and the categories present at this level."""

    tx: float
    ty: float
    beta_e: float
    ex: float
    ey: float
    phi: float
    categories: tuple[_TseCategory, ...]


# Level k (1..6) holds the samples with _TSE_L_THRESHOLDS[k-1] < L* <= _TSE_L_THRESHOLDS[k];
# L* == 0 belongs to level 1. No interpolation between levels.
_TSE_L_THRESHOLDS = (0.0, 31.0, 42.0, 51.0, 66.0, 76.0, 150.0)

# Achromatic split of the rest A = max(0, 1 - sum of chromatic memberships):
# black = A sig(-b1 (L - t1)), grey = A sig(b1 (L - t1)) sig(-b2 (L - t2)),
# white = A sig(b2 (L - t2)).
_TSE_BLACK_GREY = (28.28252201, 0.71423449)  # (t1, b1)
_TSE_GREY_WHITE = (79.64930057, 0.30674052)  # (t2, b2)

# Categories: _TseCategory(name, alpha_x, alpha_y, beta_x, beta_y).
# Benavente et al. 2008, as re-printed in Table I of Parraga et al. 2009 (same numbers as the
# CVC Barcelona implementation; level 4 differs slightly from that table's print).
_BENAVENTE_2008: tuple[_TseLevel, ...] = (
    # Level 1: 0 < L* <= 31
    _TseLevel(
        tx=0.424199636,
        ty=0.249359126,
        beta_e=9.84405931,
        ex=5.88939523,
        ey=7.47432124,
        phi=0.0405071773,
        categories=(
            _TseCategory("red", -0.0390823298, -0.986970116, 0.900991049, 1.72499209),
            _TseCategory("brown", 0.58382621, 0.25403881, 1.72499209, 0.844028374),
            _TseCategory("green", 1.82483514, 2.34898971, 0.844028374, 1.95218383),
            _TseCategory("blue", 3.91978603, -2.56831073, 1.95218383, 1.01425447),
            _TseCategory("purple", -0.997514408, -1.60987866, 1.01425447, 0.900991049),
        ),
    ),
    # Level 2: 31 < L* <= 42
    _TseLevel(
        tx=0.22956322,
        ty=0.663190063,
        beta_e=6.03260303,
        ex=6.45705135,
        ey=7.87254713,
        phi=0.30701632,
        categories=(
            _TseCategory("red", 0.0385324254, -0.851969023, 0.524362727, 5.0),
            _TseCategory("brown", 0.718827304, 0.119930098, 5.0, 0.692404886),
            _TseCategory("green", 1.69072643, 2.10250398, 0.692404886, 0.958110786),
            _TseCategory("blue", 3.67330031, -2.59153227, 0.958110786, 0.916607781),
            _TseCategory("purple", -1.02073594, -1.84515592, 0.916607781, 1.10031784),
            _TseCategory("pink", -0.274359589, -1.5322639, 1.10031784, 0.524362727),
        ),
    ),
    # Level 3: 42 < L* <= 51
    _TseLevel(
        tx=-0.117335858,
        ty=0.518007668,
        beta_e=6.81218149,
        ex=5.38109004,
        ey=6.98237582,
        phi=0.341770788,
        categories=(
            _TseCategory("red", 0.23688003, -0.794921771, 0.999376086, 0.56527939),
            _TseCategory("orange", 0.775874556, -0.502014629, 0.56527939, 0.517227023),
            _TseCategory("brown", 1.0687817, 0.116144803, 0.517227023, 0.844786041),
            _TseCategory("green", 1.68694113, 1.90897812, 0.844786041, 0.599760697),
            _TseCategory("blue", 3.47977445, -2.58725114, 0.599760697, 0.800824361),
            _TseCategory("purple", -1.01645481, -1.96583055, 0.800824361, 0.623673475),
            _TseCategory("pink", -0.39503422, -1.3339163, 0.623673475, 0.999376086),
        ),
    ),
    # Level 4: 51 < L* <= 66
    _TseLevel(
        tx=-0.44316908,
        ty=1.07591884,
        beta_e=7.3185827,
        ex=6.06365916,
        ey=7.50204671,
        phi=0.428449446,
        categories=(
            _TseCategory("red", 0.462878817, -0.995040273, 0.939107161, 0.754842803),
            _TseCategory("orange", 0.575756054, -0.172492737, 0.754842803, 0.478353741),
            _TseCategory("yellow", 1.39830359, 0.0990182597, 0.478353741, 0.728741639),
            _TseCategory("green", 1.66981459, 1.89047978, 0.728741639, 0.643832855),
            _TseCategory("blue", 3.46127611, -2.59660745, 0.643832855, 0.755213599),
            _TseCategory("purple", -1.02581112, -2.16285442, 0.755213599, 5.0),
            _TseCategory("pink", -0.592058089, -1.10791751, 5.0, 0.939107161),
        ),
    ),
    # Level 5: 66 < L* <= 76
    _TseLevel(
        tx=-0.565458039,
        ty=1.16327519,
        beta_e=100.0,
        ex=5.36820773,
        ey=6.90048122,
        phi=0.432023987,
        categories=(
            _TseCategory("orange", 0.449437961, -0.276553982, 1.99511862, 0.839910145),
            _TseCategory("yellow", 1.29424234, 0.214168287, 0.839910145, 0.856004138),
            _TseCategory("green", 1.78496461, 1.72030985, 0.856004138, 0.736644526),
            _TseCategory("blue", 3.29110617, -2.632486, 0.736644526, 0.474809095),
            _TseCategory("purple", -1.06168967, -2.13886579, 0.474809095, 1.73558321),
            _TseCategory("pink", -0.568069463, -1.12135837, 1.73558321, 1.99511862),
        ),
    ),
    # Level 6: 76 < L* <= 150
    _TseLevel(
        tx=-1.25643027,
        ty=1.8143809,
        beta_e=100.0,
        ex=6.03989989,
        ey=7.39318578,
        phi=-0.0208201846,
        categories=(
            _TseCategory("orange", 0.449316962, -0.306421502, 1.02801414, 0.790983657),
            _TseCategory("yellow", 1.26437482, 0.283461782, 0.790983657, 0.957414544),
            _TseCategory("green", 1.85425811, 1.74612759, 0.957414544, 0.900009936),
            _TseCategory("blue", 3.31692392, -2.60808914, 0.900009936, 0.598984911),
            _TseCategory("purple", -1.03729281, -2.13569227, 0.598984911, 1.93131386),
            _TseCategory("pink", -0.564895945, -1.12147936, 1.93131386, 1.02801414),
        ),
    ),
)
# Parraga et al. 2009 re-fit, as in the CVC MATLAB release of that paper (it matches Table II
# there except a few level-4 entries and beta_e = 10 at level 6, where the table prints 100).
_PARRAGA_2009: tuple[_TseLevel, ...] = (
    # Level 1: 0 < L* <= 31
    _TseLevel(
        tx=0.42419963553943735,
        ty=0.24935912601994506,
        beta_e=9.844059307641857,
        ex=5.889395231522748,
        ey=7.474321242640123,
        phi=0.04050717732657044,
        categories=(
            _TseCategory("red", -0.039082329791545856, -0.9869701163328957, 0.4, 0.5),
            _TseCategory("brown", 0.5838262104620011, -0.08726646259971647, 0.5, 0.45),
            _TseCategory("green", 1.4835298641951802, 2.007128639793479, 0.45, 0.25),
            _TseCategory("blue", 3.5779249665883754, -2.705260340591211, 0.25, 0.6),
            _TseCategory("purple", -1.1344640137963142, -1.6098786565864427, 0.6, 0.4),
        ),
    ),
    # Level 2: 31 < L* <= 42
    _TseLevel(
        tx=0.22956321976149932,
        ty=0.6631900630323688,
        beta_e=6.032603028198738,
        ex=6.457051354473343,
        ey=7.872547130141262,
        phi=0.3070163201956843,
        categories=(
            _TseCategory("red", 0.17453292519943295, -0.7853981633974483, 0.2, 0.25),
            _TseCategory("brown", 0.7853981633974483, -0.08726646259971647, 0.25, 0.45),
            _TseCategory("green", 1.4835298641951802, 2.007128639793479, 0.45, 0.25),
            _TseCategory("blue", 3.5779249665883754, -2.775073510670984, 0.25, 0.6),
            _TseCategory("purple", -1.2042771838760873, -2.007128639793479, 0.6, 0.45),
            _TseCategory("pink", -0.4363323129985824, -1.3962634015954636, 0.45, 0.2),
        ),
    ),
    # Level 3: 42 < L* <= 51
    _TseLevel(
        tx=-0.1173358578947366,
        ty=0.5180076684210526,
        beta_e=6.812181492043704,
        ex=5.381090043709867,
        ey=6.982375820487226,
        phi=0.341770787758041,
        categories=(
            _TseCategory("red", 0.2368800300332343, -0.9599310885968813, 0.25, 0.5652793904509695),
            _TseCategory(
                "orange",
                0.6108652381980153,
                -0.5020146288933987,
                0.5652793904509695,
                0.517227023219178,
            ),
            _TseCategory("brown", 1.068781697901498, 0.0, 0.517227023219178, 0.45),
            _TseCategory("green", 1.5707963267948966, 1.9547687622336491, 0.45, 0.2),
            _TseCategory("blue", 3.5255650890285457, -2.792526803190927, 0.2, 0.5),
            _TseCategory("purple", -1.2217304763960306, -1.9658305471615225, 0.5, 0.42),
            _TseCategory("pink", -0.395034220366626, -1.3339162967616622, 0.42, 0.25),
        ),
    ),
    # Level 4: 51 < L* <= 66
    _TseLevel(
        tx=-0.4431690795698924,
        ty=1.075918841935483,
        beta_e=7.318582704863765,
        ex=6.063659163640166,
        ey=7.502046706919429,
        phi=0.4284494455548185,
        categories=(
            _TseCategory("red", 0.2617993877991494, -0.994837673636768, 0.4, 0.7),
            _TseCategory("orange", 0.5759586531581288, -0.3490658503988659, 0.7, 0.45),
            _TseCategory("yellow", 1.2217304763960306, 0.09901825968532352, 0.45, 0.3),
            _TseCategory("green", 1.66981458648022, 1.9198621771937625, 0.3, 0.2),
            _TseCategory("blue", 3.490658503988659, -2.8099800957108707, 0.2, 0.4),
            _TseCategory("purple", -1.239183768915974, -2.007128639793479, 0.4, 0.25),
            _TseCategory("pink", -0.4363323129985824, -1.3089969389957472, 0.25, 0.4),
        ),
    ),
    # Level 5: 66 < L* <= 76
    _TseLevel(
        tx=-0.5654580391822832,
        ty=1.1632751925042593,
        beta_e=100.0,
        ex=5.368207727227707,
        ey=6.900481217724564,
        phi=0.43202398692090593,
        categories=(
            _TseCategory("orange", 0.5061454830783556, -0.2765539820511982, 0.6, 0.54),
            _TseCategory("yellow", 1.2942423447436984, 0.12217304763960307, 0.54, 0.47),
            _TseCategory("green", 1.6929693744344996, 1.9198621771937625, 0.47, 0.2),
            _TseCategory("blue", 3.490658503988659, -2.792526803190927, 0.2, 0.37),
            _TseCategory("purple", -1.2217304763960306, -2.0245819323134224, 0.37, 0.45),
            _TseCategory("pink", -0.4537856055185257, -1.064650843716541, 0.45, 0.6),
        ),
    ),
    # Level 6: 76 < L* <= 150
    _TseLevel(
        tx=-1.2564302704126415,
        ty=1.8143808955223852,
        beta_e=10.0,
        ex=6.039899894486615,
        ey=7.393185783452155,
        phi=-0.020820184595837267,
        categories=(
            _TseCategory("orange", 0.5061454830783556, -0.22689280275926285, 0.4, 0.6),
            _TseCategory("yellow", 1.3439035240356338, 0.1832595714594046, 0.6, 0.65),
            _TseCategory("green", 1.7540558982543015, 1.9198621771937625, 0.65, 0.25),
            _TseCategory("blue", 3.490658503988659, -2.705260340591211, 0.25, 0.35),
            _TseCategory("purple", -1.1344640137963142, -2.2252947962927703, 0.35, 0.65),
            _TseCategory("pink", -0.6544984694978736, -1.064650843716541, 0.65, 0.4),
        ),
    ),
)

_TSE_SETS: Mapping[str, tuple[_TseLevel, ...]] = MappingProxyType(
    {"benavente2008": _BENAVENTE_2008, "parraga2009": _PARRAGA_2009}
)


def _sigmoid(x: np.ndarray) -> np.ndarray:
    # sig(x) = 1 / (1 + e^-x); the exponent is clipped so saturated inputs do not overflow.
    return 1.0 / (1.0 + np.exp(-np.clip(x, -500.0, 500.0)))


def _srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """Exact sRGB (IEC 61966-2-1, D65) to CIE L*a*b* (D65 white), in float64.

    Parameters
    ----------
    rgb : (N, 3) array
        sRGB values in [0, 255].

    Returns
    -------
    (N, 3) float64 array of (L*, a*, b*).
    """
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    srgb_to_xyz = np.array(
        [
            [0.4124564, 0.3575761, 0.1804375],
            [0.2126729, 0.7151522, 0.0721750],
            [0.0193339, 0.1191920, 0.9503041],
        ]
    )
    xyz = linear @ srgb_to_xyz.T / np.array([0.95047, 1.0, 1.08883])  # / D65 white point
    epsilon, kappa = 216.0 / 24389.0, 24389.0 / 27.0  # CIE constants
    f = np.where(xyz > epsilon, np.cbrt(xyz), (kappa * xyz + 16.0) / 116.0)
    lightness = 116.0 * f[:, 1] - 16.0
    a = 500.0 * (f[:, 0] - f[:, 1])
    b = 200.0 * (f[:, 1] - f[:, 2])
    return np.stack([lightness, a, b], axis=1)


def tse_color_names(
    rgb: np.ndarray, parameter_set: TseParameterSet = "benavente2008"
) -> np.ndarray:
    """Colour-name memberships of the parametric TSE model (Benavente et al., JOSA A 2008).

    sRGB (D65) is converted to CIELAB; the lightness level k is chosen by
    ``thr[k-1] < L* <= thr[k]``. For every chromatic category present at that level, with
    ``d = (a*, b*) - t``::

        S1 = sig(beta_y ( d_a cos alpha_y + d_b sin alpha_y))
        S2 = sig(beta_x (-d_a sin alpha_x + d_b cos alpha_x))
        (u, v) = d rotated by phi,  ES = sig(beta_e ((u / ex)^2 + (v / ey)^2 - 1))
        membership = S1 * S2 * ES

    The achromatic rest ``A = max(0, 1 - sum of chromatic)`` is split into black, grey and white
    by two lightness sigmoids, and all 11 values are divided by their sum.

    Parameters
    ----------
    rgb : (N, 3) array
        sRGB values in [0, 255] (any numeric dtype).
    parameter_set : {"benavente2008", "parraga2009"}
        The original 2008 fit (default; its argmax agrees with ``w2c.mat`` on about 78 % of the
        32768 bins) or the 2009 re-fit of Parraga et al. (about 74 %).

    Returns
    -------
    (N, 11) float64 array
        Probabilities in :data:`COLOR_NAMES` order; every row sums to 1.

    Notes
    -----
    The model was fitted to Munsell chips in CIELAB. Both parameter sets name the sRGB primary
    red (255, 0, 0) "orange" (its hue angle, 40 degrees at L* = 53, lies past the model's
    red/orange boundary) and the primary blue (0, 0, 255) "purple" (CIELAB bends blues towards
    purple); slightly darker reds such as (200, 0, 0) and blues such as (0, 100, 255) are red
    and blue. ``w2c.mat`` names both primaries red and blue.
    """
    if parameter_set not in _TSE_SETS:
        raise ValueError(f"parameter_set must be one of {sorted(_TSE_SETS)}, got {parameter_set!r}")
    rgb = np.asarray(rgb)
    if rgb.ndim != 2 or rgb.shape[1] != 3:
        raise ValueError(f"rgb must have shape (N, 3), got {rgb.shape}")
    lab = _srgb_to_lab(rgb)
    lightness, a, b = lab[:, 0], lab[:, 1], lab[:, 2]

    # side="left" gives k with thr[k-1] < L <= thr[k]; L == 0 (k = 0) joins level 1.
    level = np.clip(np.searchsorted(_TSE_L_THRESHOLDS, lightness, side="left"), 1, 6)
    memberships = np.zeros((rgb.shape[0], len(COLOR_NAMES)))
    for k, params in enumerate(_TSE_SETS[parameter_set], start=1):
        at_level = level == k
        if not at_level.any():
            continue
        d_a = a[at_level] - params.tx
        d_b = b[at_level] - params.ty
        # Elliptical centre shared by all categories of the level: ~0 inside, ~1 outside.
        u = d_a * np.cos(params.phi) + d_b * np.sin(params.phi)
        v = -d_a * np.sin(params.phi) + d_b * np.cos(params.phi)
        es = _sigmoid(params.beta_e * ((u / params.ex) ** 2 + (v / params.ey) ** 2 - 1.0))
        for cat in params.categories:
            s1 = _sigmoid(cat.beta_y * (d_a * np.cos(cat.alpha_y) + d_b * np.sin(cat.alpha_y)))
            s2 = _sigmoid(cat.beta_x * (-d_a * np.sin(cat.alpha_x) + d_b * np.cos(cat.alpha_x)))
            memberships[at_level, COLOR_NAMES.index(cat.name)] = s1 * s2 * es

    achromatic = np.maximum(0.0, 1.0 - memberships.sum(axis=1))
    (t1, b1), (t2, b2) = _TSE_BLACK_GREY, _TSE_GREY_WHITE
    memberships[:, COLOR_NAMES.index("black")] = achromatic * _sigmoid(-b1 * (lightness - t1))
    memberships[:, COLOR_NAMES.index("grey")] = (
        achromatic * _sigmoid(b1 * (lightness - t1)) * _sigmoid(-b2 * (lightness - t2))
    )
    memberships[:, COLOR_NAMES.index("white")] = achromatic * _sigmoid(b2 * (lightness - t2))
    # The sum is positive: either the chromatic part is >= 1 or the achromatic rest is > 0 and
    # the three lightness sigmoids cannot all vanish.
    return memberships / memberships.sum(axis=1, keepdims=True)


def _bin_centres() -> np.ndarray:
    """RGB values ``8 i + 4`` at the centre of each of the 32768 bins, in row order, (N, 3)."""
    row = np.arange(N_COLOR_BINS)
    return np.stack([row % 32, (row // 32) % 32, row // 1024], axis=1) * 8 + 4


def _validate_table(table: object, source: str) -> np.ndarray:
    """Check that ``table`` is a (32768, 11) per-row probability table; return it as float64."""
    if not isinstance(table, np.ndarray) or not np.issubdtype(table.dtype, np.number):
        kind = table.dtype if isinstance(table, np.ndarray) else type(table).__name__
        raise ColorNamesError(f"{source}: expected a numeric (32768, 11) array, got {kind}")
    if table.shape != (N_COLOR_BINS, len(COLOR_NAMES)):
        raise ColorNamesError(
            f"{source}: expected shape ({N_COLOR_BINS}, {len(COLOR_NAMES)}) (32^3 RGB bins x "
            f"11 colour names), got {table.shape}"
        )
    table = table.astype(np.float64)
    if not np.isfinite(table).all():
        raise ColorNamesError(f"{source}: expected finite probabilities, found NaN or inf")
    if table.min() < -_ROW_SUM_TOLERANCE:
        raise ColorNamesError(
            f"{source}: expected non-negative probabilities, minimum is {table.min():.3g}"
        )
    deviation = np.abs(table.sum(axis=1) - 1.0)
    worst = int(deviation.argmax())
    if deviation[worst] > _ROW_SUM_TOLERANCE:
        n_bad = int((deviation > _ROW_SUM_TOLERANCE).sum())
        raise ColorNamesError(
            f"{source}: expected every row to sum to 1 (probabilities over 11 colour names), "
            f"but {n_bad} rows do not; row {worst} sums to {table[worst].sum():.6g}"
        )
    return np.clip(table, 0.0, None)


def load_w2c_table(path: str | os.PathLike[str]) -> np.ndarray:
    """Read the van de Weijer et al. (2009) ``w2c.mat`` colour-name table (thesis §3.1.1).

    Parameters
    ----------
    path : str or path-like
        A MATLAB v5 file holding the variable ``w2c`` of shape (32768, 11).

    Returns
    -------
    (32768, 11) float64 array
        Probabilities in :data:`COLOR_NAMES` order, rows summing to 1.

    Raises
    ------
    ColorNamesError
        If the file is missing, is not a readable MATLAB file, has no ``w2c`` variable, or
        ``w2c`` is not a (32768, 11) table of probabilities.
    """
    path = Path(path)
    if not path.is_file():
        raise ColorNamesError(f"colour-name table {str(path)!r} does not exist or is not a file")
    try:
        contents = read_mat(path)
    except ValueError as err:
        raise ColorNamesError(f"colour-name table {str(path)!r}: {err}") from err
    if "w2c" not in contents:
        found = sorted(k for k in contents if not k.startswith("__"))
        raise ColorNamesError(
            f"{str(path)!r} has no variable 'w2c'; found {found or 'no variables'}"
        )
    return _validate_table(contents["w2c"], f"'w2c' in {str(path)!r}")


def zero_sum_basis(n: int) -> np.ndarray:
    """Orthonormal basis of the hyperplane ``sum(x) = 0`` in R^n (thesis §3.2.1).

    The columns are the Helmert contrasts: column ``k`` (1-based) is
    ``(1, ..., 1, -k, 0, ..., 0) / sqrt(k (k + 1))`` with ``k`` leading ones. Together with
    ``(1, ..., 1) / sqrt(n)`` they form an orthonormal basis of R^n, so for any ``p``,
    ``B @ (B.T @ p) = p - mean(p)``: projecting drops only the constant direction.

    Parameters
    ----------
    n : int
        Dimension of the probability vectors (11 for Color Names); at least 2.

    Returns
    -------
    (n, n - 1) float64 array with orthonormal columns orthogonal to the ones vector.
    """
    if n < 2:
        raise ValueError(f"n must be at least 2, got {n}")
    basis = np.zeros((n, n - 1))
    for k in range(1, n):
        basis[:k, k - 1] = 1.0
        basis[k, k - 1] = -float(k)
        basis[:, k - 1] /= np.sqrt(k * (k + 1.0))
    return basis


class ColorNameTable:
    """RGB to Color Names lookup: raw 11-dim probabilities and the 10-dim normalised feature.

    The table is evaluated at most once per instance (on first use when it is computed from the
    embedded TSE model) and stored read-only; share one instance between trackers to share it.

    Parameters
    ----------
    probabilities : (32768, 11) array or callable
        The table (rows are probabilities in :data:`COLOR_NAMES` order, indexed by
        ``r // 8 + 32 (g // 8) + 1024 (b // 8)``), or a zero-argument function returning it,
        called on first use.
    source : str
        Human-readable origin of the table, used in messages and ``repr``.

    See Also
    --------
    ColorNameTable.from_config : the embedded model unless a ``w2c.mat`` path is configured.
    """

    def __init__(
        self, probabilities: np.ndarray | Callable[[], np.ndarray], *, source: str
    ) -> None:
        self.source = source
        if callable(probabilities):
            self._produce = probabilities
        else:
            table = _validate_table(probabilities, source)  # validate now, at the boundary
            self._produce = lambda: table

    @classmethod
    def embedded(cls, parameter_set: TseParameterSet = "benavente2008") -> ColorNameTable:
        """The TSE model (Benavente et al. 2008) evaluated at the 32768 bin centres, lazily."""
        if parameter_set not in get_args(TseParameterSet):
            raise ValueError(
                f"parameter_set must be one of {get_args(TseParameterSet)}, got {parameter_set!r}"
            )
        return cls(
            lambda: tse_color_names(_bin_centres(), parameter_set), source=f"tse:{parameter_set}"
        )

    @classmethod
    def from_w2c(cls, path: str | os.PathLike[str]) -> ColorNameTable:
        """The ``w2c.mat`` table of van de Weijer et al. (2009), loaded and checked now.

        Raises
        ------
        ColorNamesError
            See :func:`load_w2c_table`.
        """
        return cls(load_w2c_table(path), source=f"w2c:{os.fspath(path)}")

    @classmethod
    def from_config(
        cls,
        w2c_path: str | os.PathLike[str] | None = None,
        parameter_set: TseParameterSet = "benavente2008",
    ) -> ColorNameTable:
        """The ``w2c.mat`` table at ``w2c_path`` if one is configured, else the embedded model."""
        if w2c_path is None or os.fspath(w2c_path) == "":
            return cls.embedded(parameter_set)
        return cls.from_w2c(w2c_path)

    @cached_property
    def probabilities(self) -> np.ndarray:
        """(32768, 11) float64, read-only: the raw colour-name probabilities per RGB bin."""
        table = _validate_table(self._produce(), self.source)
        table.flags.writeable = False
        return table

    @cached_property
    def table11(self) -> np.ndarray:
        """(32768, 11) float32, read-only: the raw probabilities as a lookup table."""
        table = self.probabilities.astype(np.float32)
        table.flags.writeable = False
        return table

    @cached_property
    def table10(self) -> np.ndarray:
        """(32768, 10) float32, read-only: the normalised Color Names lookup table (§3.2.1).

        Row ``i`` is ``B.T @ (p_i - 1/11)`` with ``B = zero_sum_basis(11)``: the probabilities in
        an orthonormal basis of the hyperplane orthogonal to ``(1, ..., 1)``, constant dropped.
        (``B.T @ 1 = 0``, so subtracting 1/11 first only removes rounding.)
        """
        centred = self.probabilities - 1.0 / len(COLOR_NAMES)
        table = (centred @ zero_sum_basis(len(COLOR_NAMES))).astype(np.float32)
        table.flags.writeable = False
        return table

    @staticmethod
    def bin_indices(image: np.ndarray) -> np.ndarray:
        """Table row of every pixel, ``r // 8 + 32 (g // 8) + 1024 (b // 8)``, shape (H, W)."""
        q = (require_rgb(image, "cn") >> 3).astype(np.intp)  # bin 0..31 per channel
        return q[..., 0] + 32 * q[..., 1] + 1024 * q[..., 2]

    def probabilities_at(self, image: np.ndarray) -> np.ndarray:
        """Raw colour-name probabilities of an RGB uint8 image, float32 (H, W, 11)."""
        return self.table11[self.bin_indices(image)]

    def __call__(self, image: np.ndarray) -> np.ndarray:
        """Normalised Color Names feature (thesis §3.2.1) of an RGB uint8 image.

        Returns
        -------
        (H, W, 10) float32
            One table lookup per pixel; each pixel's values are the centred probabilities in an
            orthonormal basis, so ``|x| <= sqrt(10/11)`` and the L2 geometry is preserved.
        """
        return self.table10[self.bin_indices(image)]

    def __repr__(self) -> str:
        return f"{type(self).__name__}(source={self.source!r})"
