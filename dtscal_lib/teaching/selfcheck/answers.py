"""The course's predictions: each question, its tolerance and its explanation, keyed by the question.

The student notebooks hold only the question (a comment beside ``predict_... = None``) and a call
``check_prediction("01.width_ratio", predict_width_ratio, measured, **facts)`` after the experiment
(:func:`.predict.check_prediction`). The answer is what the experiment measures; the explanation is
written here, outside the notebook, so that nothing the student reads before running the check gives
it away (issue 29). ``giveaways`` lists the phrases that would: ``tests/test_predictions_hidden.py``
scans every student notebook for them.

An explanation is a function of the measured value ``m``, the student's prediction ``p`` (``None``
when missing) and the experiment's facts ``f`` (keyword arguments of the call), so it can say with the
student's own number why the prediction was right or wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

__all__ = ["Question", "QUESTIONS", "question"]


@dataclass(frozen=True)
class Question:
    """One prediction: what is asked, how it is judged, and why the answer is what it is."""

    key: str  #: "NN.name": the notebook and the question
    var: str  #: the notebook variable the student fills in
    text: str  #: the question as the check prints it
    why: Callable[[object, object, dict], str]
    choices: tuple[str, ...] = ()  #: a choice question's answers; empty for a number
    atol: float = 0.0
    rtol: float = 0.0
    unit: str = ""
    digits: int = 2
    #: phrases that give the answer away: never in a student notebook (sources, prose, outputs before the check)
    giveaways: tuple[str, ...] = field(default=())

    @property
    def is_choice(self) -> bool:
        return bool(self.choices)


def _near(p, x, tol) -> bool:
    try:
        return p is not None and abs(float(p) - x) <= tol
    except (TypeError, ValueError):
        return False


def _yours(p, unit: str = "", digits: int = 2) -> str:
    return f"{float(p):.{digits}f}{' ' + unit if unit else ''}"


# ----------------------------------------------------------------------------------------------- 01
def _why_width_ratio(m, p, f):
    text = ("straight on, every corner has the same depth Z, and u - cx = f X / Z: the whole picture scales by the "
            "ratio of the distances, 0.45 / 0.28 = 1.61. Doubling f would scale it the same way: that is why one "
            "straight-on view cannot tell f from distance.")
    if _near(p, 0.28 / 0.45, 0.04):
        text += f" Your {_yours(p)} is 0.28 / 0.45, upside down: the nearer board looks bigger, not smaller."
    elif _near(p, (0.45 / 0.28) ** 2, 0.15):
        text += (f" Your {_yours(p)} is the ratio squared: that is how the board's area grows; its width grows "
                 "as 1 / Z only.")
    return text


def _why_yaw60(m, p, f):
    text = (f"the explorer swings the camera AROUND the board at {f['distance']:.1f} m, always looking at the board's "
            f"centre: the centre stays on the optical axis, so turning only foreshortens the board (at 60 deg it "
            f"spans u = {f['u_min']:.0f} to {f['u_max']:.0f} px, about cos 60 = 0.5 of its straight-on width, "
            "still centred).")
    if p is not None and str(p).strip().lower() == "leave":
        text += (f" 'leave' is what a camera turned about its OWN centre would do: the board would slide out once the "
                 f"turn passes half the field of view, atan(320 / fx) = {f['half_fov_deg']:.0f} deg. The explorer's "
                 "sliders do the other thing; to move the board in the image, use its shift sliders.")
    return text


def _why_tilt40(m, p, f):
    half = 3 * 0.031 * math.sin(math.radians(40))  # half the board's 6 squares, turned by 40 deg
    text = ("straight on (tilt 0) they are identical. A tilted board has near and far corners; doubling the "
            f"distance brings their depths closer in ratio (the board's 18.6 cm width turned by 40 deg spans about "
            f"{100 * 2 * half:.0f} cm of depth: {0.4 - half:.2f}-{0.4 + half:.2f} m, a ratio of "
            f"{(0.4 + half) / (0.4 - half):.2f}, becomes {0.8 - half:.2f}-{0.8 + half:.2f} m, a ratio of "
            f"{(0.8 + half) / (0.8 - half):.2f}), which no focal length can mimic. The few pixels left are all a "
            "calibration has to separate f from distance: more tilt, more pixels, a better calibration.")
    if _near(p, 0.0, 0.5):
        text += (f" Your {_yours(p, 'px')} is the straight-on answer: the tie between f and distance holds only "
                 "while every corner has the same depth.")
    elif p is not None and _near(p, m * 10, m * 5):
        text += (f" Your {_yours(p, 'px')} would make f and distance easy to tell apart from one view; it takes "
                 "many tilted views because the difference is only a few pixels.")
    return text


# ----------------------------------------------------------------------------------------------- 02
def _why_residual(m, p, f):
    text = (f"the best homography leaves {f['rms']:.2f} px RMS on frame {f['frame']}. The Duckiebot's wide lens bends "
            "the board's rows, which no 3x3 matrix can do, so the best H can only compromise. The residual is the "
            "lens, not the detector (whose corners are good to about 0.1 px): notebook 04 models it.")
    if p is not None and str(p).strip().lower() == "below 0.1 px":
        text += " 'below 0.1 px' is the detector's accuracy: it would hold for a pinhole camera, not for this lens."
    return text


def _why_same_h(m, p, f):
    return ("the normalization moves every point set to its own centroid and mean distance sqrt(2) before fitting, "
            "so any offset or scale you apply first is undone: the normalized DLT sees the same numbers and returns "
            f"the same homography (its error against the truth changed by {f['spread']:.2f} px across the "
            "coordinate choices in the table). The unnormalized DLT weighs the equations differently in each "
            "coordinate system, so its answer, and its error against the truth, changes with an arbitrary choice.")


def _why_lifted(m, p, f):
    text = (f"in this pose (0.4 m, tilted) lifting a corner by 1 cm moves its pixel by {f['shift_lo']:.1f}-"
            f"{f['shift_hi']:.1f} px: only the part of the lift across the line of sight shows. The best H then "
            "spreads the misfit over all corners, half of them not lifted, so the RMS is about half of that. This is "
            "why a calibration board must be flat, and why the ground homography of notebook 05 is only right for "
            "points ON the ground.")
    if _near(p, 310 * 0.01 / 0.4, 1.0):
        text += (f" Your {_yours(p, 'px')} is f x 1 cm / 0.4 m, a lift seen square on and fully unexplained; "
                 "neither holds here.")
    return text


# ----------------------------------------------------------------------------------------------- 03
def _why_rank_parallel(m, p, f):
    text = ("a board moved without turning has the same vanishing points h1, h2 (directions do not move when you "
            f"translate), so every view repeats the same 2 equations: the rank is {m:.0f}, and {5 - m:.0f} of the 5 "
            "intrinsics stay free however many views you add.")
    if _near(p, 20, 0.5):
        text += " Your 20 counts 2 equations per view, but parallel views give the SAME two equations each time."
    elif _near(p, 5, 0.5):
        text += " 5 is what views tilted in different directions reach (the 'tilted' row)."
    return text


def _why_fronto(m, p, f):
    return ("straight on, the vanishing points h1, h2 lie at infinity (their third entry is 0), so the equations see "
            f"only the top-left 2x2 of B ({f['involved']}): they fix the aspect ratio fy/fx and the skew, and nothing "
            "about B13, B23, B33, where the principal point and the focal length live. It is notebook 01's ambiguity: "
            "straight on, f trades off against distance.")


def _why_closed_form(m, p, f):
    return (f"the closed form misses the true K by {f['err_px']:.1f} px here, a hundred times the corner noise. "
            "Zhang's equations assume a pinhole; the lens's barrel distortion makes every homography a compromise "
            "(next cell).")


# ----------------------------------------------------------------------------------------------- 03b
def _why_full_rms(m, p, f):
    return (f"the full calibration leaves {f['rms']:.3f} px RMS, the closed form {f['rms_cf']:.2f} px. A model with "
            "every piece the camera has (pinhole and lens distortion) leaves only the detector's corner noise, a "
            "small fraction of a pixel; the closed form lacks the distortion and leaves pixels of systematic error, "
            "largest near the image edges.")


def _why_verdict(m, p, f):
    return ("the verdict cannot know the truth: it judges the fit against the corner noise and how loosely the data "
            "pin the parameters down (their uncertainty), not the error against the truth. A calibration a fraction "
            "of a pixel from the truth can still be 'doubtful' when the views leave parts of the image bare; the "
            "warnings above (when there are any) name what to do.")


def _why_three_views(m, p, f):
    return (f"with {f['noise_px']} px of corner noise, 3 views miss K by {f['err_3']:.1f} px (the table's first row). "
            "3 views give 6 equations for the 5 unknowns: almost no redundancy, so the corner noise goes straight "
            "into K, amplified by the homographies' sensitivity; each view added averages it down, which is why the "
            "error falls with the number of views.")


# ----------------------------------------------------------------------------------------------- 04
def _why_fov(m, p, f):
    text = ("the angle between the rays through the left and right image edges, found by undoing the lens: barrel "
            "distortion squeezes a wider view into the same 640 px than a pinhole with this focal length, "
            f"2 atan(320 / fx) = {f['pinhole_deg']:.0f} deg, could show.")
    if _near(p, f["pinhole_deg"], 8):
        text += f" Your {_yours(p, 'deg', 0)} is close to that pinhole answer: the lens adds the rest."
    return text


def _why_corner_shift(m, p, f):
    K, dist = f["K"], f["dist"]
    x, y = -K[0][2] / K[0][0], -K[1][2] / K[1][1]  # the top-left image corner, normalized
    r2 = x * x + y * y
    rho = 1 + dist[0] * r2 + dist[1] * r2 * r2
    reach = math.hypot(K[0][2], K[1][2])
    text = (f"at a corner r^2 = x^2 + y^2 is about {r2:.2f} in normalized units, so rho = 1 + k1 r^2 + k2 r^4 is about "
            f"{rho:.2f}: the point is pulled {100 * (1 - rho):.0f} % of the way towards the centre, "
            f"{100 * (1 - rho):.0f} % of the corner's {reach:.0f} px distance from it.")
    if _near(p, reach * (1 - rho) * 0.3, reach * (1 - rho) * 0.25):
        text += (f" Your {_yours(p, 'px', 0)} would fit a mild lens; at the corners of this one the r^4 and r^2 "
                 "terms are large.")
    return text


def _why_alpha0(m, p, f):
    return (f"the new fx is {f['new_fx']:.1f} px against K's {f['fx']:.1f} px. A shorter focal length shows a wider "
            "view. The rectified (pinhole) image must show the largest rectangle the lens saw; the barrel lens saw "
            "more than a pinhole with K's focal length can fit in 640 px, so even that rectangle needs a smaller f.")


# ----------------------------------------------------------------------------------------------- 05
def _why_height(m, p, f):
    text = ("the scale of H^-1 is fixed by the ground's unit axes, so the camera centre -R^T t comes out in metres: "
            "its z is the height above the ground.")
    if _near(p, m / 100, 0.05):
        text += f" Your {_yours(p, 'cm', 2)} looks like metres: the question asks for centimetres."
    return text


def _why_pitch(m, p, f):
    text = ("R's third row is where the camera looks, written in the robot's axes; its z component, -sin(pitch), says "
            "how far below the horizon. A steeper camera sees the road closer to the wheels.")
    if _near(p, math.radians(m), 0.05):
        text += f" Your {_yours(p, 'deg', 2)} is the pitch in radians: the question asks for degrees."
    elif _near(p, -m, 5):
        text += " Your sign is flipped: the pitch counts positive BELOW the horizon, where a Duckiebot's camera looks."
    return text


def _why_yaw(m, p, f):
    yaw, x = f["yaw_deg"], f["x_ahead_m"]
    text = (f"the calibration takes the board's axes for the robot's, so the whole ground turns by the yaw: a point x "
            f"ahead moves x sin(yaw) sideways, {1000 * x:.0f} mm x sin({yaw:g} deg) = "
            f"{1000 * x * math.sin(math.radians(yaw)):.0f} mm, far more than the fit's own error above. Align the robot "
            "on the printed marks.")
    if _near(p, 1000 * x * math.sin(yaw), 5):
        text += f" Your {_yours(p, 'mm', 0)} took {yaw:g} as radians: sin wants radians, math.radians({yaw:g}) first."
    elif _near(p, 1000 * x * math.sin(math.radians(yaw)) * 2, 3):
        text += " Your value is twice that: the error grows with x sin(yaw), not 2 x sin(yaw)."
    return text


_BANDS = ("below 1 px", "1-10 px", "above 10 px")

QUESTIONS: dict[str, Question] = {q.key: q for q in [
    Question("01.width_ratio", "predict_width_ratio",
             "how many times wider does the board look at 0.28 m than at 0.45 m?", _why_width_ratio,
             rtol=0.05, giveaways=("0.45 / 0.28 = 1.61", "scales by the ratio of the distances")),
    Question("01.yaw60", "predict_yaw60", "at yaw 60 deg, does the board stay inside the image or leave it?",
             _why_yaw60, choices=("inside", "leave"),
             giveaways=("narrower, still centred", "only foreshortens", "never leaves the image")),
    Question("01.tilt40_px", "predict_tilt40_px",
             "tilted 40 deg: by how many px do (f, 0.4 m) and (2f, 0.8 m) differ?", _why_tilt40,
             atol=2.0, unit="px", giveaways=("a ratio of 1.35",)),
    Question("02.residual", "predict_residual", "RMS residual of the best homography on a recorded frame?",
             _why_residual, choices=("below 0.1 px", "0.1-1 px", "above 1 px"),
             giveaways=("the best H can only compromise",)),
    Question("02.same_H", "predict_same_H", "origin moved 1000 px away: does the normalized DLT's answer change?",
             _why_same_h, choices=("yes", "no"), giveaways=("gives the same H", "returns the same homography")),
    Question("02.lifted_px", "predict_lifted_px",
             "every other board corner lifted 1 cm: RMS residual (px) of the best homography?", _why_lifted,
             atol=1.0, unit="px", giveaways=("spreads the misfit",)),
    Question("03.rank_parallel", "predict_rank_parallel", "10 parallel boards: the rank of V?", _why_rank_parallel,
             atol=0.5, digits=0, giveaways=("rank 2", "the same 2 equations", "same two equations")),
    Question("03.fronto_unknown", "predict_fronto_unknown",
             "boards all facing the camera squarely: which intrinsics stay unknown?", _why_fronto,
             choices=("focal length and principal point", "skew and aspect ratio", "none"),
             giveaways=("where the principal point and the focal length live",)),
    Question("03.closed_form", "predict_closed_form", "the closed form on the recorded corners misses the true K by?",
             _why_closed_form, choices=_BANDS, giveaways=("makes every homography a compromise",)),
    Question("03b.full_rms", "predict_full_rms", "the full calibration's RMS residual over all views?",
             _why_full_rms, choices=("below 0.5 px", "0.5-2 px", "above 2 px"),
             giveaways=("leaves only the detector's corner noise",)),
    Question("03b.verdict", "predict_verdict", "the kit's verdict on the full calibration?", _why_verdict,
             choices=("good", "doubtful", "bad"), giveaways=("the verdict cannot know the truth",)),
    Question("03b.three_views", "predict_three_views",
             "3 well-tilted views with noisy corners: the closed form misses the true K by?", _why_three_views,
             choices=_BANDS, giveaways=("almost no redundancy",)),
    Question("04.fov_deg", "predict_fov_deg", "horizontal field of view of the lens (degrees)?", _why_fov,
             atol=10, unit="deg", digits=0, giveaways=("117 deg",)),
    Question("04.corner_shift", "predict_corner_shift", "how far (px) does the lens move the point at an image corner?",
             _why_corner_shift, rtol=0.25, unit="px", digits=0,
             giveaways=("31 % of the corner", "moves an image corner by 131")),
    Question("04.alpha0_f", "predict_alpha0_f", "alpha = 0: is the new focal length larger or smaller than K's?",
             _why_alpha0, choices=("larger", "smaller"),
             giveaways=("needs a smaller f", "needs a *shorter* focal length", "shorter focal length than")),
    Question("05.height_cm", "predict_height_cm", "camera height (cm)?", _why_height, atol=2.0, unit="cm", digits=1,
             giveaways=("about 10 cm above the ground", "10.4 cm up", "cm above the ground, 18")),
    Question("05.pitch_deg", "predict_pitch_deg", "pitch below the horizon (deg)?", _why_pitch, atol=5.0, unit="deg",
             digits=1, giveaways=("pitched 18 deg", "a few tens of degrees")),
    Question("05.yaw_mm", "predict_yaw_mm", "the robot stood turned by 2 deg: sideways error 0.5 m ahead (mm)?",
             _why_yaw, atol=5.0, unit="mm", digits=1, giveaways=("= 17 mm", "by 17.4 mm")),
]}


def question(key: str) -> Question:
    """The question ``key`` ("01.width_ratio"); a clear error naming the known keys otherwise."""
    try:
        return QUESTIONS[key]
    except KeyError:
        raise KeyError(f"no prediction question {key!r}; known: {', '.join(sorted(QUESTIONS))}") from None
