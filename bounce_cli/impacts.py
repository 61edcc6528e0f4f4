"""The impacts table (``impacts.csv``): one row per bounce, the interface between the data
side's extraction (``bounce extract``, recordings -> impacts) and every data analysis
(``--data impacts.csv``). A lab may also write this table itself.

Columns (units in the names; phases are the racket's phase of impact, section 2, eq. 6 with
``theta_k = omega_r t_k`` per racket cycle):

======================  ==========================================================================
``trial``               trial label (statistics never cross a trial boundary)
``k``                   impact index within the trial (0, 1, ...)
``t_s``                 time of the impact, s
``theta_rad``           phase of impact, wrapped to [0, 2 pi)
``theta_deg``           the same in degrees, [0, 360)
``v_m_s``               ball velocity just after the impact, m/s (the map's v_k)
``racket_acc_g``        racket acceleration at impact in units of g (AC, section 4)
``racket_period_s``     period of the racket cycle in which the impact falls, s
``racket_amplitude_m``  amplitude of that racket cycle, m
``hop_s``               time to the next impact, s (empty for a trial's last impact)
``ball_apex_m``         highest ball position of the following flight, relative to the racket's
                        mid-position, m
``alpha``               coefficient of restitution of this impact (optional: from events)
``perturbed``           True where alpha was changed at this impact (optional: from events)
======================  ==========================================================================
"""

from __future__ import annotations

#: the columns every impacts table has, in this order
REQUIRED_COLUMNS: tuple[str, ...] = (
    "trial",
    "k",
    "t_s",
    "theta_rad",
    "theta_deg",
    "v_m_s",
    "racket_acc_g",
    "racket_period_s",
    "racket_amplitude_m",
    "hop_s",
    "ball_apex_m",
)
#: columns present when the recording came with events (a virtual set-up's log)
EVENT_COLUMNS: tuple[str, ...] = ("alpha", "perturbed")
