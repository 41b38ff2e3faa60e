"""The parameters of the SVGF denoiser (:class:`DenoiserSettings`), checked when made.

Defaults follow Falcor's SVGFPass (``alpha_min``, ``moments_alpha_min``, ``phi_color``,
``phi_normal``, ``phi_depth``) and NRD's RELAX (the fast history and its clipping); ``iterations``,
``clip_gamma``, ``antilag``, ``firefly_ratio`` and ``firefly_sigma`` were retuned for issue 29's FLIP
goal on real renders (docs/denoising.md, "Perceptual quality at 8 frames");
where this implementation departs from them (``variance_of_mean``, ``feedback_tap``, ``clip_gamma``)
the default was measured with ``bench/evaluations/denoise_passes.py quality``: the relMSE against the noise-free
image of a static synthetic scene after 4, 8 and 16 frames, its steady decrease, and how fast a
lighting change is followed (docs/denoising-passes.md has the tables); ``firefly_ratio`` was chosen on
real renders against 4096-spp references.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields

from pyclpt.common.checks import check_bool, check_float, check_int

#: ``clip_radius`` values: the fast-history box is 3x3 or 5x5 pixels.
CLIP_RADII = (1, 2)


@dataclass
class DenoiserSettings:
    """Every parameter of the SVGF denoiser. Change a field and pass the object again (or call
    :meth:`validate`); a bad value raises ValueError (TypeError for the wrong kind) naming the field."""

    #: Smallest weight of the frame in the long colour history, max(alpha_min, 1/N): the history is
    #: the plain mean of the first 1/alpha_min frames, then an exponential moving average.
    #: Falcor's 0.05 (about 39 effective frames at convergence).
    alpha_min: float = 0.05
    #: The same for the luminance moments that estimate the variance (Falcor's 0.2: the variance
    #: follows changes within a few frames).
    moments_alpha_min: float = 0.2
    #: The same for the fast history that bounds the long one (RELAX keeps about 6 frames in it).
    #: Chosen with clip_gamma, measured together (docs/denoising-passes.md): 0.5 with clip_gamma 3
    #: follows a drop of the lighting twice as fast as RELAX-like 0.2 with 2, and converges as well
    #: on a static scene.
    fast_alpha: float = 0.5
    #: Clip the reprojected long history into mean +- clip_gamma sigma of the fast history around the
    #: pixel, per channel (RELAX's history clamping; what removes ghosting when the lighting
    #: changes), the box widened to hold the pixel's own fast history (so a pixel whose history equals
    #: its own fast history is never clipped, whatever its neighbours). Negative: no clipping.
    #: Measured with clip_radius (docs/denoising.md, "Energy"): the 3x3 box at 3 sigma darkened the
    #: cornell-box's red channel by 0.6 % after 32 frames (its 9 skewed samples often underestimate
    #: the spread); the 5x5 box at 2.5 sigma by 0.1 to 0.2 %, and follows the synthetic 4x light
    #: drop of tests/test_denoise.py about as fast (relMSE 0.42 after 8 frames against 0.32 for 3x3 at
    #: 3 sigma; 1.32 unclipped). Widened to 6 sigma with the same-frame anti-lag (issue 29's FLIP goal,
    #: docs/denoising.md, "Perceptual quality at 8 frames"): the fast histories' 1-sample noise is
    #: skewed, so a tight box clips the bright side of a young long history more often than the dark
    #: side and darkens it; on the cornell-box at 120x120, frame 8, FLIP 0.0818 at 2.5 sigma, 0.0764
    #: at 6 (at 256x256: 0.0694, 0.0603). The anti-lag, not the box, catches a change of the light.
    clip_gamma: float = 6.0
    #: Half-size of the fast-history box: 1 (3x3) or 2 (5x5). Compiled in (-DCLIP_RADIUS).
    clip_radius: int = 2
    #: Anti-lag (NRD RELAX's idea as a test statistic; cl/denoise/clip_history.cl, cl/denoise/antilag.cl):
    #: t, the distance between the mean of the fast histories and the mean of the long ones over the
    #: clip box, in standard errors of the fast mean, its largest channel averaged over the 3x3 pixels
    #: around p. The same frame cuts the history length N to about (N - 1) (1 - a) + 1, a =
    #: clamp(4 (t - antilag) / antilag, 0, 1): from t = 1.25 antilag on the history restarts from the
    #: frame (colour, fast, moments and emission histories). A change of the lighting moves the fast
    #: histories within a frame or two; clipping alone does not catch a uniform 4x drop under 1-sample
    #: noise (its box is as wide as the noise). 0: off; off too where clip_gamma < 0. Measured in
    #: docs/denoising-passes.md ("Anti-lag") and docs/denoising.md ("The light change, in the same
    #: frame"): 4 when the cut was made a frame late from one pixel's t; 3.5 with the 3x3 mean, which
    #: restarts no history of tests/test_denoise.py's static noisy scene in 16 frames and brings the
    #: cornell-box's error in the frame of a light change from 0.447 to 0.052 (120x120).
    antilag: float = 3.5
    #: The anti-lag's threshold (if lower than ``antilag``) in the ``antilag_frames`` frames after the lighting
    #: changed in view (cl/denoise/light_age.cl: at least 1/400 of the pixels saw a light change: light_changed in
    #: reproject). A light turned down changes the light of every surface it reaches in that frame, but the dim,
    #: noisy ones (a box's face lit only indirectly) show it to the statistic only over several frames; at 3.5
    #: they kept the old light for tens of frames (the cornell-box's light change: lag "never"; docs/denoising.md,
    #: "The light change: cutting more readily after it").
    antilag_changed: float = 1.5
    #: How many frames after a light changed in view ``antilag_changed`` holds (0: never). On the cornell-box's
    #: light change at 120x120, 4 frames at 1.5 bring the lag from "never" to 0; 8 frames at 1.0 cut on noise.
    antilag_frames: int = 4
    #: The firefly clamp (cl/denoise/reproject.cl): the frame's demodulated luminance is clamped to
    #: sqrt(N) x the larger of firefly_ratio x a spatial reference (the largest of its 3x3 neighbours'
    #: mean, centre excluded, their temporal means and the history's luminance) and the pixel's own
    #: temporal moments, mean + firefly_sigma x sigma; N the history length after this frame, so the
    #: clamp relaxes as the history grows and the denoised mean converges to the accumulated one. No
    #: clamp where there is no reference at all (a 1x1 image's first frame). 0: no clamp (a 1000x
    #: firefly then spreads over the whole filter footprint). The fixed clamp of before (firefly_ratio
    #: x the reference, not relaxed) removed 1.1 to 2.1 % of the image's energy on the cornell-box at
    #: 64x64 after 32 frames, the relaxed one 0.1 to 0.2 % (tests/test_denoise_energy.py). The ratio 4
    #: was chosen on real renders at 1 sample per pixel and frame (docs/denoising-passes.md, "The
    #: firefly clamp on real renders") and raised to 8 with firefly_sigma 6 for issue 29's FLIP goal:
    #: at 8 frames the clamp at 4 still took enough of the 1-sample tail to darken the cornell-box
    #: visibly (FLIP 0.0758 at 120x120 with iterations 3, 0.0694 at 8 and firefly_sigma 6, 0.0630
    #: without a clamp; docs/denoising.md).
    firefly_ratio: float = 8.0
    #: Give the firefly clamp's deficit back (cl/denoise/deficit.cl, modulate.cl): what the clamp took
    #: from the samples is accumulated per pixel as the long history is, its share of the light measured
    #: per 16x16 tile, and modulate adds the tile's share of its mean illumination, the share at most 5 x
    #: the mean share of the 3x3 tiles around, the largest left out (a lone firefly's tile gives nothing
    #: back). docs/denoising.md, "The clamp's deficit given back" and "Energy at 32 frames".
    give_back: bool = True
    #: Keep the a-trous filter's energy (cl/denoise/conserve.cl, modulate.cl): per 8x8 tile and channel,
    #: the filtered illumination is scaled so that its sum (weighed by the albedo) is the unfiltered
    #: one's, the gains bilinear between the tiles' centres. The filter is a normalised gather, and a
    #: bright pixel with a loose luminance weight beside quiet ones gives more light away than they take
    #: in: on the evaluation's captured frames (issue 29) the filter cost the cornell-bunny 0.4 % at 32
    #: frames (0.9885 of the plain average's, 0.992 with the filter's input). A tile's gain is its own,
    #: its excess over 1 at most 10 x the robust mean of the 3x3 tiles' (a lone firefly's tile gets
    #: none: tests/test_denoise.py::test_firefly_is_confined_and_fades), moved towards 1 by the share of
    #: the tile's short histories (after a light change the filter's loss is the old light), and ramped
    #: in per pixel from 2 to 8 frames of history (the filter dims a light's edge on a short history on
    #: purpose). Measured on the same frames, this change alone (the table of docs/denoising.md, "Energy
    #: at 32 frames", has the others): the bunny's 32-frame means 0.9918 / 0.9905 / 0.9907 (0.9885 /
    #: 0.9883 / 0.9886 without), the cornell-box's 0.9999 to 1.0001 (1.0011 to 1.0016); at frame 8 FLIP
    #: 1.066 x OIDN's on the box (1.145), 1.201 on the bunny (1.258), 1.165 in the living room (1.197),
    #: relMSE 0.105, 0.033 and 0.337 x the plain average's (0.111, 0.033, 0.345).
    conserve: bool = True
    #: The filter's energy balance keeps of a tile's loss e the part that stands out of the noise of the
    #: tile's unfiltered light, e^2 / (e^2 + conserve_sigma^2 v) of it, v the variance of that light's sum
    #: (cl/denoise/conserve.cl): most of a tile's loss is its noise crossing its border, which the full gain
    #: put back as 8-pixel blotches. 0: the full gain. On the cornell-box at 256x256, frame 8, FLIP 1.26 x
    #: OIDN's with 1, 1.32 with 0 (docs/denoising.md, "The filter's balance without the tiles' noise").
    conserve_sigma: float = 1.0
    #: The firefly clamp's temporal term: mean + firefly_sigma x sigma of the pixel's luminance moments
    #: (before the sqrt(N) relaxation). On the cornell-box at 64x64, 1, 2 and 3 give the same relMSE
    #: within 2 % at 8 and 32 frames; 6 with firefly_ratio 8 (see there). Half of it also scales the
    #: neighbourhood's term, mean + firefly_sigma / 2 x the sigma of the 3x3 neighbours' moments
    #: (cl/denoise/reproject.cl), so that a pixel keeps the rare bright samples its neighbours have
    #: drawn (docs/denoising.md, "Energy at 8 frames").
    firefly_sigma: float = 6.0
    #: A-trous iterations (steps 1, 2, 4, ...): the filter reaches 2 (2^iterations - 1) pixels; at most
    #: 8. Falcor's 5 was the largest single cost of FLIP at 8 frames (issue 29, docs/denoising.md):
    #: the iterations at steps 8 and 16, whose variance the earlier ones have already shrunk, keep a
    #: few far taps each and leave blotches and stripes across a whole face of the cornell-box. Its
    #: FLIP at 120x120, frame 8, with 1 to 5 iterations: 0.091, 0.084, 0.086, 0.092, 0.095; relMSE
    #: 0.0072, 0.0047, 0.0047, 0.0054, 0.0059 (at 256x256 3 is best too: FLIP 0.0758 against 0.0799).
    iterations: int = 3
    #: The a-trous iteration whose output becomes the colour history (Falcor: 1, SVGF's paper: 0);
    #: -1: the history keeps the unfiltered temporal accumulation. Measured: with a filtered history
    #: the error stops falling after 8 frames (tap 0) or grows again (taps 1, 2), the filter's bias
    #: being fed back; -1 keeps converging (relMSE 3x (tap 0) to 6x (tap 1) lower after 32 frames).
    feedback_tap: int = -1
    #: sigma_l of the luminance edge-stopping weight ``exp(-|l_p - l_q| / (phi_color sqrt(var)))``.
    #: Falcor's 10 (the paper's 4).
    phi_color: float = 10.0
    #: Exponent of the normal weight max(0, cos)^phi_normal (Falcor's 128).
    phi_normal: float = 128.0
    #: sigma_z of the depth weight ``exp(-|dz| / (phi_depth |grad z| step |offset|))`` (Falcor's 1).
    phi_depth: float = 1.0
    #: Reprojection: a previous pixel is the same surface if ``|z - z_prev| <= depth_threshold x
    #: (depth gradient + 0.01 z)``. A bilinear tap is at most one pixel away per axis, so 1 would pass
    #: any smooth surface at rest; 4 also allows 4 % of depth change a frame along the view.
    depth_threshold: float = 4.0
    #: Reprojection: and if the cosine between the normals is at least this (0.8: about 37 degrees).
    normal_threshold: float = 0.8
    #: History length cap N (Falcor's 32); the colour weight is max(alpha_min, 1/N), so above
    #: 1/alpha_min this only bounds the count history_length() reports.
    max_history: int = 32
    #: Half-size of the spatial variance estimate on a short history (N < 4): 1 (3x3), 2 (5x5) or 3
    #: (Falcor's 7x7). The first frame's relMSE on the bench's synthetic scene at 96x64 / 256x192 and
    #: on the Cornell box at 64x64: 1: 20.3e-3 / 11.5e-3 / 0.033, 2: 19.0e-3 / 9.0e-3 / 0.057, 3:
    #: 18.6e-3 / 8.0e-3 / 0.093; 2 is the middle, at half the cost of 7x7 (scalar code on PoCL: 149
    #: instead of 278 ms for a first frame at 1280x720).
    variance_radius: int = 2
    #: Steer the a-trous filter by the variance of the accumulated estimate (the per-sample variance
    #: over min(N, (2 - alpha_min) / alpha_min)) rather than plain SVGF's per-sample variance, so the
    #: spatial filter weakens as the history converges and the output keeps converging (measured:
    #: without it the error stalls from 8 frames on, 2.3x higher after 16 and 3.7x after 32).
    variance_of_mean: bool = True

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> DenoiserSettings:
        """Check every field; returns self. ValueError/TypeError name the field and the value."""
        name = type(self).__name__
        for field in ("alpha_min", "moments_alpha_min", "fast_alpha"):
            value = check_float(getattr(self, field), f"{name}.{field}", lo=0.0, hi=1.0)
            if value <= 0.0:
                raise ValueError(f"{name}.{field} must be in (0, 1] (a blend weight; 0 would never take a "
                                 f"new frame), got {value}")
            setattr(self, field, value)
        self.clip_gamma = check_float(self.clip_gamma, f"{name}.clip_gamma")
        self.clip_radius = check_int(self.clip_radius, f"{name}.clip_radius", lo=1, hi=2)
        self.antilag = check_float(self.antilag, f"{name}.antilag", lo=0.0)
        self.antilag_changed = check_float(self.antilag_changed, f"{name}.antilag_changed", lo=0.0)
        self.antilag_frames = check_int(self.antilag_frames, f"{name}.antilag_frames", lo=0, hi=1 << 16)
        self.firefly_ratio = check_float(self.firefly_ratio, f"{name}.firefly_ratio", lo=0.0)
        self.firefly_sigma = check_float(self.firefly_sigma, f"{name}.firefly_sigma", lo=0.0)
        self.conserve_sigma = check_float(self.conserve_sigma, f"{name}.conserve_sigma", lo=0.0)
        if 0.0 < self.firefly_ratio < 1.0:
            raise ValueError(f"{name}.firefly_ratio must be 0 (off) or >= 1 (a clamp below the neighbours' "
                             f"mean would darken every pixel), got {self.firefly_ratio}")
        self.iterations = check_int(self.iterations, f"{name}.iterations", lo=0, hi=8,
                                    note=" (the buffers' padding covers 8)")
        self.feedback_tap = check_int(self.feedback_tap, f"{name}.feedback_tap", lo=-1, hi=7,
                                      note=" (-1 = the unfiltered accumulation)")
        if self.feedback_tap >= self.iterations:
            raise ValueError(f"{name}.feedback_tap={self.feedback_tap} names an a-trous iteration that does not "
                             f"run with iterations={self.iterations} (use -1 or 0..{self.iterations - 1})")
        for field in ("phi_color", "phi_depth"):
            value = check_float(getattr(self, field), f"{name}.{field}", lo=0.0)
            if value <= 0.0:
                raise ValueError(f"{name}.{field} must be > 0 (it divides a difference), got {value}")
            setattr(self, field, value)
        self.phi_normal = check_float(self.phi_normal, f"{name}.phi_normal", lo=0.0)
        self.depth_threshold = check_float(self.depth_threshold, f"{name}.depth_threshold", lo=0.0)
        self.normal_threshold = check_float(self.normal_threshold, f"{name}.normal_threshold", lo=-1.0, hi=1.0)
        self.max_history = check_int(self.max_history, f"{name}.max_history", lo=1, hi=1 << 20)
        self.variance_radius = check_int(self.variance_radius, f"{name}.variance_radius", lo=1, hi=3)
        self.variance_of_mean = check_bool(self.variance_of_mean, f"{name}.variance_of_mean")
        self.give_back = check_bool(self.give_back, f"{name}.give_back")
        self.conserve = check_bool(self.conserve, f"{name}.conserve")
        return self

    @property
    def n_eff_max(self) -> float:
        """What variance.cl divides the variance by at most: (2 - alpha_min) / alpha_min, or 1 (plain
        SVGF) without variance_of_mean."""
        return (2.0 - self.alpha_min) / self.alpha_min if self.variance_of_mean else 1.0

    def as_dict(self) -> dict[str, object]:
        """The settings as a dictionary, field name to value."""
        return asdict(self)

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The settings' field names, in declaration order."""
        return tuple(f.name for f in fields(cls))

