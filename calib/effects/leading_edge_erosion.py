"""Leading-edge erosion or roughness of the outboard blade: drag rise and loss of C_L,max."""

from __future__ import annotations

import numpy as np

from calib.effects.base import Effect, attached_weight, smoothstep, stall_weight
from calib.types import Parameter


class LeadingEdgeErosion(Effect):
    """Drag rise and lift loss near stall outboard of an onset span (polar stage).

    Parameters
    ----------
    variant : {"stall", "slope"}
        Where the lift is lost: ``"stall"`` (default) near stall only, a loss of C_L,max;
        ``"slope"`` over the whole attached range, a loss of lift slope (heavier roughness,
        or another author's erosion model). Both compete in a diagnosis; the better names the
        effect.
    ramp_width : float
        Width Δη over which the damage ramps in from the onset span [-]. Default 0.1.
    stall_width_deg : float
        Width of the rise of the lift loss before the stall angle [deg]. Default 8.
    nominal : dict, optional
        Nominal values of ``erosion_onset_eta``, ``erosion_drag_rise``, ``erosion_lift_loss``.

    Notes
    -----
    With the onset span η0, the spanwise ramp R(η) = S((η − η0)/Δη) (S the C¹ smoothstep
    3t² − 2t³ on [0, 1]), a drag rise ΔC_D,e and a relative lift loss m:

    .. math::
        C_D = C_{D,2D} + ΔC_{D,e}\\,R(η)\\,w_D(α),\\qquad
        C_L = C_{L,2D}\\,(1 − m\\,R(η)\\,w_L(α))

    w_D = 1 for |α| <= 20 deg, falling (C¹) to 0 at 40 deg (roughness adds skin-friction and
    transition drag to attached flow; separated flow is dominated by pressure drag);
    w_L rises (C¹) from 0 at α_s − 8 deg to 1 at the station's stall angle α_s (maximum of
    its C_L on 0…30 deg) and fades from 25 to 45 deg (variant ``"stall"``), or w_L = w_D
    (variant ``"slope"``: a lift-slope loss over the attached range, as a roughness that
    thickens the boundary layer everywhere gives): eroded and rough leading edges trip
    the boundary layer early and lower C_L,max (Sareen et al. 2014; Abbott & von Doenhoff's
    "standard roughness" polars), with little change of the lift slope at low α.

    All three are parameters; the drag rise and the lift loss are bounded below by 0: erosion
    and roughness never make a section cleaner than its 2-D polar (a fit that wants a lift gain
    or a drag reduction is another effect, e.g. rotational augmentation, not negative erosion).
    At zero damage (ΔC_D,e = m = 0, the nominal) the outputs do
    not depend on η0: its derivative is zero there, and it becomes identifiable only with a
    non-zero magnitude.

    Fingerprint: C_P low at every tip-speed ratio, by the largest absolute amount near the
    optimal λ where most power is made on the outboard blade; in the correction field,
    ΔC_D > 0 on η > η0 (and ΔC_L < 0 near stall there).

    References
    ----------
    A. Sareen, C.A. Sapre, M.S. Selig, Effects of leading edge erosion on wind turbine blade
    performance, Wind Energy 17 (2014) 1531-1542.
    I.H. Abbott, A.E. von Doenhoff, Theory of Wing Sections, Dover (1959), standard roughness data.
    """

    name = "leading_edge_erosion"
    stage = "polar"
    fingerprint = ("C_P low at every tip-speed ratio, most (absolute) near the optimal lambda; Delta C_D > 0 "
                   "outboard of the onset span, lift loss near stall there")
    OPTIONS = {"variant": "stall", "ramp_width": 0.1, "stall_width_deg": 8.0}
    CHOICES = {"variant": ("stall", "slope")}
    PARAMETERS = (
        Parameter("erosion_onset_eta", 0.7, 0.3, 0.95, 0.05, "-", "effect",
                  description="span r/R where the erosion starts", prior_std=0.15),
        Parameter("erosion_drag_rise", 0.0, 0.0, 0.05, 0.003, "-", "effect",
                  description="drag-coefficient rise of the eroded sections", prior_std=0.01),
        Parameter("erosion_lift_loss", 0.0, 0.0, 0.5, 0.05, "-", "effect",
                  description="relative C_L loss near stall of the eroded sections", prior_std=0.1),
    )

    def apply(self, theta, state, ctx):
        eta0, drag_rise, lift_loss = theta
        ramp = smoothstep((ctx.eta - eta0) / float(self.options["ramp_width"]))
        a = state.alpha_deg
        alpha_stall = np.clip(ctx.rotor.features.alpha_stall_deg[ctx.station], 5.0, 20.0)
        w_d = attached_weight(a, 20.0, 40.0)
        w_l = stall_weight(a, alpha_stall, float(self.options["stall_width_deg"])) \
            if self.options["variant"] == "stall" else w_d
        cd = state.cd + drag_rise * ramp * w_d
        cl = state.cl * (1.0 - lift_loss * ramp * w_l)
        return state.replace(cl=cl, cd=cd)
