"""Configuration of the circulant-structure trackers (thesis ch. 2-4), one frozen object.

Defaults are the values of Table 2.1 (gamma 0.075, lambda 0.01, eta 1.0, sigma_y 1/16,
sigma_kappa 0.2) and of §4.3 (mu 0.1 for the linear kernel, 0.15 otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Learner = Literal["mosse", "csk", "rcsk", "strcf"]
KernelName = Literal["linear", "polynomial", "gaussian"]


@dataclass(frozen=True, slots=True)
class ScaleConfig:
    """The scale-adaptive mode: a one-dimensional correlation filter over a pyramid of scales.

    Not in the thesis; it follows the discriminative scale-space filter of Danelljan et al.
    (BMVC 2014), the same author's continuation, because people and cars change size.

    Attributes
    ----------
    num_scales:
        Number of scale samples S around the current size (odd).
    scale_step:
        Ratio a between neighbouring scale samples; they span ``a**(-(S-1)/2) .. a**((S-1)/2)``.
    label_sigma_factor:
        Standard deviation of the Gaussian label over scales, times ``sqrt(S)``.
    learning_rate:
        Update rate of the scale filter (its own gamma).
    regularization:
        Lambda of the scale filter.
    model_max_area:
        Pixels of the resampled target patch used as one scale sample (bounds the cost).
    min_scale_factor, max_scale_factor:
        Bounds on the scale relative to the first frame.
    feature:
        Features of the scale samples (same syntax as ``CorrelationConfig.feature``), pooled
        on 4-pixel cells; ``None`` uses the tracker's own. Cheap per-pixel features keep the
        ``2 S`` samples per frame affordable.
    """

    num_scales: int = 17
    scale_step: float = 1.03
    label_sigma_factor: float = 0.25
    learning_rate: float = 0.025
    regularization: float = 0.01
    model_max_area: int = 512
    min_scale_factor: float = 0.2
    max_scale_factor: float = 5.0
    feature: str | None = None

    def __post_init__(self) -> None:
        if self.num_scales < 3 or self.num_scales % 2 == 0:
            raise ValueError(f"num_scales must be odd and >= 3, got {self.num_scales}")
        if self.scale_step <= 1.0:
            raise ValueError(f"scale_step must be > 1, got {self.scale_step}")
        if not 0.0 < self.learning_rate <= 1.0:
            raise ValueError(f"scale learning_rate must be in (0, 1], got {self.learning_rate}")


@dataclass(frozen=True, slots=True)
class AdmmSchedule:
    """The augmented-Lagrangian penalty ``gamma`` over the ADMM iterations of one STRCF frame.

    ``gamma`` starts at ``initial`` and after each iteration becomes ``min(step * gamma,
    maximum)`` (STRCF eq. 10). The reference code's values (1, 0.1, 10) make it 1 for the first
    iteration and 0.1 for the second.
    """

    iterations: int = 2
    initial: float = 1.0
    maximum: float = 0.1
    step: float = 10.0

    def __post_init__(self) -> None:
        if self.iterations < 1:
            raise ValueError(f"ADMM iterations must be >= 1, got {self.iterations}")
        if min(self.initial, self.maximum, self.step) <= 0.0:
            raise ValueError("the ADMM penalty, its maximum and its step must be positive")

    def penalties(self) -> list[float]:
        """The ``gamma`` of each iteration."""
        values, gamma = [], self.initial
        for _ in range(self.iterations):
            values.append(gamma)
            gamma = min(self.step * gamma, self.maximum)
        return values


@dataclass(frozen=True, slots=True)
class CorrelationConfig:
    """Every tunable number of a circulant-structure tracker.

    Attributes
    ----------
    learner:
        ``"mosse"`` (eq. 2.4, linear, one filter per feature channel), ``"csk"`` (eq. 2.10 with
        interpolated coefficients), ``"rcsk"`` (the proposed robust learning, eq. 2.21) or
        ``"strcf"`` (beyond the thesis: the spatially and temporally regularised filter of
        Li et al. 2018, :mod:`tracking.correlation.regularized`).
    kernel:
        Kernel of CSK/RCSK: ``"linear"``, ``"polynomial"`` (eq. 2.15) or ``"gaussian"`` (eq. 2.23).
        Ignored by MOSSE and STRCF.
    feature:
        Feature representation (§3.1), components joined by ``+``: e.g. ``"gray"``, ``"cn"``,
        ``"gray+cn"`` (the thesis's proposed combination), ``"hog+cn"``.
    learning_rate:
        gamma of eq. 2.4 and 2.21 (Table 2.1: 0.075).
    regularization:
        lambda of eq. 2.2, 2.10 and 2.20 (Table 2.1: 0.01).
    padding:
        eta: the patch is ``(1 + eta)`` times the target size (Table 2.1: 1.0).
    label_sigma:
        sigma_y of the label function, eq. 2.22, relative to ``sqrt(s1 s2)`` (Table 2.1: 1/16).
    kernel_sigma:
        sigma_kappa of the Gaussian kernel, eq. 2.23 (Table 2.1: 0.2).
    polynomial_offset, polynomial_degree:
        The polynomial kernel ``(<f, g> / (MND) + offset) ** degree``.
    compressed_dim:
        D2 of the adaptive dimensionality reduction (Algorithms 4.1-4.2); ``None`` keeps all
        feature dimensions.
    projection_learning_rate:
        mu of Algorithm 4.1; ``None`` takes the thesis's value for the kernel (§4.3: 0.1 for
        the linear kernel, 0.15 for the others).
    cell_size:
        Pixels per feature cell. 1 for the thesis's per-pixel colour features; HOG needs >= 2
        (4 is usual) and per-pixel features are averaged over each cell.
    square_patch:
        Make the patch a square of the same area instead of the target's shape (STRCF's
        search region, whose context then reaches further along a tall target's width).
    max_patch_area:
        Patches larger than this many pixels are resampled down to it before feature
        extraction, bounding the cost for large targets; ``None`` never resamples (the thesis).
    min_patch_side:
        Patches whose short side is below this many pixels are resampled up to it (but not
        past ``max_patch_area``), so that small targets still get a grid of enough cells;
        0 never enlarges (the thesis).
    color_names_path:
        The van de Weijer ``w2c.mat`` table for Color Names; ``None`` uses the embedded
        parametric colour-naming model.
    subpixel:
        Refine the response peak with a parabola through its neighbours.
    scale:
        The scale-adaptive mode, or ``None`` for a fixed target size (the thesis).
    temporal_regularization:
        mu of STRCF (eq. 3; the paper's 15): how strongly each frame's filter stays close to
        the previous one, in place of a learning rate. STRCF only.
    admm:
        The ADMM iterations and penalties of each STRCF frame.
    compressed_features:
        ``(component, dimensions)`` pairs: each named component of :attr:`feature` is projected
        onto its first principal components on the first frame, and the projection is kept
        (ECO's factorised convolution, Danelljan et al. 2017, initialised as ECO does by PCA
        of the first sample, without its Gauss-Newton refinement; ECO-HC: HOG to 10, Color
        Names to 3). Fewer channels make every transform and ADMM step cheaper. STRCF only.
    search_scales:
        STRCF's own scale search: the translation filter is evaluated on this many samples
        (odd) whose sizes step by ``search_scale_step`` around the current one, and the
        sample with the highest peak gives position and scale (the paper: 5 at 1.01). 1
        searches the current size only. An alternative to :attr:`scale`, not an addition.
    search_scale_step:
        The size ratio between neighbouring scale samples of :attr:`search_scales`.
    apce_ratio, peak_ratio:
        The failure signal (Wang et al., CVPR 2017, "LMCF"): a frame whose response has an
        average peak-to-correlation energy below ``apce_ratio`` times the mean of the frames
        before, and a peak below ``peak_ratio`` times theirs, is reported occluded and not
        learnt from (the paper's 0.7 and 0.45). ``0`` disables either test; both 0 learn
        from every frame (the thesis).
    """

    learner: Learner = "rcsk"
    kernel: KernelName = "gaussian"
    feature: str = "gray+cn"
    learning_rate: float = 0.075
    regularization: float = 0.01
    padding: float = 1.0
    label_sigma: float = 1.0 / 16.0
    kernel_sigma: float = 0.2
    polynomial_offset: float = 1.0
    polynomial_degree: int = 2
    compressed_dim: int | None = None
    projection_learning_rate: float | None = None
    cell_size: int = 1
    square_patch: bool = False
    max_patch_area: int | None = None
    min_patch_side: int = 0
    color_names_path: str | None = None
    subpixel: bool = True
    scale: ScaleConfig | None = None
    temporal_regularization: float = 15.0
    admm: AdmmSchedule = AdmmSchedule()
    compressed_features: tuple[tuple[str, int], ...] = ()
    search_scales: int = 1
    search_scale_step: float = 1.01
    apce_ratio: float = 0.0
    peak_ratio: float = 0.0

    def __post_init__(self) -> None:
        # imported here: the configuration stays cheap to import for those who only read it
        from tracking.features.registry import feature_components

        feature_components(self.feature)  # an unknown feature fails here, not in the tracker
        if self.learner not in ("mosse", "csk", "rcsk", "strcf"):
            raise ValueError(
                f"learner must be 'mosse', 'csk', 'rcsk' or 'strcf', got {self.learner!r}"
            )
        if self.kernel not in ("linear", "polynomial", "gaussian"):
            raise ValueError(
                f"kernel must be 'linear', 'polynomial' or 'gaussian', got {self.kernel!r}"
            )
        if not 0.0 < self.learning_rate <= 1.0:
            raise ValueError(f"learning_rate must be in (0, 1], got {self.learning_rate}")
        if self.regularization < 0.0:
            raise ValueError(f"regularization must be >= 0, got {self.regularization}")
        if self.padding < 0.0:
            raise ValueError(f"padding must be >= 0, got {self.padding}")
        if self.label_sigma <= 0.0 or self.kernel_sigma <= 0.0:
            raise ValueError("label_sigma and kernel_sigma must be positive")
        if self.cell_size < 1:
            raise ValueError(f"cell_size must be >= 1, got {self.cell_size}")
        if self.compressed_dim is not None:
            if self.compressed_dim < 1:
                raise ValueError(f"compressed_dim must be >= 1, got {self.compressed_dim}")
            if self.learner in ("mosse", "strcf"):
                raise ValueError(
                    "compressed_dim needs a kernel learner ('csk' or 'rcsk'): MOSSE and STRCF "
                    "keep one filter per feature channel, which a changing projection would "
                    "invalidate"
                )
        if self.temporal_regularization < 0.0:
            raise ValueError(
                f"temporal_regularization must be >= 0, got {self.temporal_regularization}"
            )
        if self.compressed_features:
            if self.learner != "strcf":
                raise ValueError("compressed_features needs learner 'strcf'")
            names = feature_components(self.feature)
            for name, dims in self.compressed_features:
                if name not in names or dims < 1:
                    raise ValueError(
                        f"compressed_features: {name!r} to {dims} dimensions, but the feature "
                        f"is {self.feature!r} and dimensions must be >= 1"
                    )
        if self.search_scales < 1 or self.search_scales % 2 == 0:
            raise ValueError(f"search_scales must be odd and >= 1, got {self.search_scales}")
        if self.search_scales > 1:
            if self.learner != "strcf":
                raise ValueError("search_scales > 1 needs learner 'strcf'")
            if self.scale is not None:
                raise ValueError("search_scales > 1 replaces the scale filter: set scale=None")
            if self.search_scale_step <= 1.0:
                raise ValueError(f"search_scale_step must be > 1, got {self.search_scale_step}")
        if self.apce_ratio < 0.0 or self.peak_ratio < 0.0:
            raise ValueError("apce_ratio and peak_ratio must be >= 0")
        if self.min_patch_side < 0:
            raise ValueError(f"min_patch_side must be >= 0, got {self.min_patch_side}")
        if self.max_patch_area is not None and self.max_patch_area < 64:
            raise ValueError(f"max_patch_area must be >= 64 pixels, got {self.max_patch_area}")

    @property
    def colour_features(self) -> tuple[str, ...]:
        """The components of :attr:`feature` that read colour (``("cn",)`` of ``"gray+cn"``):
        all but the intensity ones, ``gray`` and ``hog``, which see a greyscale video as they
        see a colour one."""
        from tracking.features.registry import feature_components

        return tuple(c for c in feature_components(self.feature) if c not in ("gray", "hog"))

    @property
    def mu(self) -> float:
        """The projection learning rate mu of Algorithm 4.1 (§4.3 defaults)."""
        if self.projection_learning_rate is not None:
            return self.projection_learning_rate
        return 0.1 if self.kernel == "linear" else 0.15
