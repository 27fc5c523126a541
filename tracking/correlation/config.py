"""Configuration of the circulant-structure trackers (thesis ch. 2-4), one frozen object.

Defaults are the values of Table 2.1 (gamma 0.075, lambda 0.01, eta 1.0, sigma_y 1/16,
sigma_kappa 0.2) and of §4.3 (mu 0.1 for the linear kernel, 0.15 otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Learner = Literal["mosse", "csk", "rcsk"]
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
class CorrelationConfig:
    """Every tunable number of a circulant-structure tracker.

    Attributes
    ----------
    learner:
        ``"mosse"`` (eq. 2.4, linear, one filter per feature channel), ``"csk"`` (eq. 2.10 with
        interpolated coefficients) or ``"rcsk"`` (the proposed robust learning, eq. 2.21).
    kernel:
        Kernel of CSK/RCSK: ``"linear"``, ``"polynomial"`` (eq. 2.15) or ``"gaussian"`` (eq. 2.23).
        Ignored by MOSSE.
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
    max_patch_area: int | None = None
    min_patch_side: int = 0
    color_names_path: str | None = None
    subpixel: bool = True
    scale: ScaleConfig | None = None

    def __post_init__(self) -> None:
        # imported here: the configuration stays cheap to import for those who only read it
        from tracking.features.registry import feature_components

        feature_components(self.feature)  # an unknown feature fails here, not in the tracker
        if self.learner not in ("mosse", "csk", "rcsk"):
            raise ValueError(f"learner must be 'mosse', 'csk' or 'rcsk', got {self.learner!r}")
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
            if self.learner == "mosse":
                raise ValueError(
                    "compressed_dim needs a kernel learner ('csk' or 'rcsk'): MOSSE keeps one "
                    "filter per feature channel, which a changing projection would invalidate"
                )
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
