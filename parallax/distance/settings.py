"""The distance learner's settings (distance.*; paper §3.5–3.5.2, eqs. 9–15) and the planned
route's (movement.*, beyond the paper, §7) beside their checks.

Every setting as a typed dataclass field with its one default, the choices it allows, and the
checks of the values a type cannot rule out (parallax.checks).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from omegaconf import MISSING

from parallax.checks import Checks
from parallax.distance.estimators import ESTIMATORS
from parallax.distance.targets import TARGET_SOURCES, OdometryConfig

#: distance.input_scaling: the network's input processing (parallax.distance.network).
INPUT_SCALINGS = ("global", "per_input", "none")
#: movement.route: the paper's sweep of L, or the route the robot plans (beyond the paper, §7).
ROUTES = ("list", "planned")


@dataclass
class SensitivityConfig:
    """Which lateral positions are sensitive (§3.5.1, eq. 10, Table 1): disparity score at the
    nearest distance ≥ P_e − tolerance, with P_e = P_l·√P_s."""

    #: P_l, the patch side in pixels.
    patch: int = 10
    #: P_s of the coarse scale, so P_e = 10·√8 ≈ 28.3 px.
    subsample: float = 8.0
    #: Metres; Table 1's disparity scores are at 3 m.
    nearest_distance: float = 3.0
    #: Pixels below P_e still counted as sensitive: 15 cm (26.6 px) is, 14 cm (24.8 px) is not
    #: (the paper's "larger than or approximately equal to").
    tolerance: float = 2.5


@dataclass
class LevenbergMarquardtConfig:
    """The network's Levenberg–Marquardt fit (§3.5, [33]), with MATLAB trainlm's μ schedule."""

    #: μ, the damping the first step starts from (trainlm's mu).
    mu: float = 1.0e-3
    #: μ is multiplied by this after a step that lowered the error (trainlm's mu_dec).
    mu_decrease: float = 0.1
    #: μ is multiplied by this after a step that did not (trainlm's mu_inc).
    mu_increase: float = 10.0
    #: The fit stops when μ grows past this (trainlm's mu_max).
    mu_max: float = 1.0e10
    #: Stop when ‖Jᵀe‖ falls below this.
    min_grad: float = 1.0e-7
    #: Refuse larger models: the step solves a dense parameters × parameters system.
    max_params: int = 5000
    #: Refuse fits whose Jacobian (queued vectors × parameters) would be larger.
    max_jacobian_elements: int = 20_000_000
    #: Beyond trainlm: minimise Σe² + weight_decay·‖w‖² (w: all weights and biases, in the
    #: network's scaled units); a queue of c = 100 vectors and 541 parameters otherwise overfits
    #: (0: trainlm, the paper).
    weight_decay: float = 0.1


@dataclass
class DistanceConfig:
    """Egocentric distance learner (§3.5–3.5.2, eqs. 9–15): queue memory, sensitive-position
    weighting, MLP r → hidden sigmoid → 1, trained by Levenberg–Marquardt."""

    _target_: str = "parallax.distance.DistanceLearner"
    #: Filled by the trainer: the lateral list L in metres (curriculum.lateral_positions).
    lateral_positions: list[float] = MISSING
    #: c, the queue memory's length (eq. 9; §4.2 uses 300).
    queue_size: int = 300
    #: Hidden sigmoid units (eqs. 13–14; §3.5.2 uses 30).
    hidden: int = 30
    #: Weigh the sensitive positions' inputs (eqs. 10–12); false: the plain inputs.
    weighting: bool = True
    #: y of eq. (12), w_k = 1/((1 + l_r − l_k)·y) with lengths in cm; the paper gives no value.
    y: float = 1.0
    sensitivity: SensitivityConfig = field(default_factory=SensitivityConfig)
    #: LM epochs each time a new s arrives (warm start); the paper trains "every iteration".
    epochs_per_call: int = 10
    #: LM epochs of the first fit, when the queue has just filled.
    initial_epochs: int = 100
    lm: LevenbergMarquardtConfig = field(default_factory=LevenbergMarquardtConfig)
    #: Where the targets come from (parallax.distance.targets.TARGET_SOURCES): supervisor, the
    #: true distances (§3.5) | odometry, beyond the paper (§7's second future work): the strides
    #: of the robot's own walk to the panel (``odometry``, env.walk).
    targets: str = "supervisor"
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    #: Fits start once the queue holds this many vectors; null: once it is full (§3.5). Fewer
    #: targets arrive when only some presentations are labelled (odometry.walk_fraction < 1).
    fit_from: int | None = None
    #: The network's input processing (INPUT_SCALINGS): global, one
    #: mapminmax over all of S | per_input, MATLAB's mapminmax, each position scaled on its own
    #: (which cancels the weighting) | none, the pans as they are, a new network's initial
    #: weights spread over each input's range (MATLAB's initnw).
    input_scaling: str = "global"
    #: Share of the queue each fit holds out to stop on (MATLAB's dividerand; 0: none): the fit
    #: stops after ``max_fail`` epochs in a row whose error on these vectors rose, and keeps the
    #: weights of its best epoch, as MATLAB's train does.
    validation_fraction: float = 0.0
    #: Share of the queue each fit leaves out altogether (dividerand's test set; 0: none).
    test_fraction: float = 0.0
    #: Epochs in a row with a rising validation error that stop a fit (MATLAB's max_fail).
    max_fail: int = 6
    #: Start every fit from lm.mu, as each call of MATLAB's train does; false: carry μ over
    #: from the last fit (the queue changes by one vector).
    reset_mu: bool = False
    #: Each fit starts from the last fit's weights, as calling MATLAB's train again on the same
    #: network does; false: from new random weights each time (a program that builds its
    #: network again before each call), for ``initial_epochs``.
    warm_start: bool = True
    #: With a warm start, keep the [−1, 1] scaling of the first fit, as MATLAB's train does (it
    #: configures mapminmax only on a network not yet configured); false: refit it to each fit's
    #: queue, the weights re-expressed so that the network's function is unchanged.
    keep_first_scaling: bool = False
    #: What reads a distance from s, one of parallax/distance/estimators/: network, the MLP
    #: above (eqs. 13–15), as in the paper.
    estimator: str = "network"
    #: Filled by the trainer: the network's initialisation seed.
    seed: int = MISSING


@dataclass
class MovementConfig:
    """Beyond the paper (its first future work, §7): the robot chooses where to move next and
    when to stop (parallax.distance.planner), instead of sweeping all of L."""

    #: list: every position of L in order, every presentation (the paper) | planned: the robot
    #: plans its route from its confidence (one robot, supervisor targets).
    route: str = "list"
    #: planned: what one trial (t_h eye movements) costs, in percentage points of expected
    #: distance error.
    price_per_trial: float = 0.1
    #: planned: what one centimetre of lateral travel (out to the farthest position and back)
    #: costs, in percentage points of expected distance error.
    price_per_cm: float = 0.0
    #: planned: the probability that a training presentation sweeps all of L instead; the
    #: planner and the distance network learn from those sweeps (and every presentation sweeps
    #: until the planner's queue of c sweeps is full).
    explore: float = 0.25


def check(check: Checks) -> None:
    queue = check.integer("distance.queue_size", 1, " (the queue length c)")
    hidden = check.integer("distance.hidden", 1, " (hidden units)")
    check.number("distance.y", above=0, what=" (eq. 12's y)")
    check.integer("distance.sensitivity.patch", 1, " (pixels)")
    check.number("distance.sensitivity.subsample", at_least=1)
    check.number("distance.sensitivity.nearest_distance", above=0, what=" (metres)")
    check.number("distance.sensitivity.tolerance", at_least=0, what=" (pixels)")
    check.integer("distance.epochs_per_call", 1)
    check.integer("distance.initial_epochs", 1)
    lm = "distance.lm"
    check.number(f"{lm}.mu", above=0)
    check.number(f"{lm}.mu_decrease", above=0, below=1)
    check.number(f"{lm}.mu_increase", above=1)
    check.number(f"{lm}.mu_max", above=0)
    check.number(f"{lm}.min_grad", at_least=0)
    check.number(f"{lm}.weight_decay", at_least=0)
    max_params = check.integer(f"{lm}.max_params", 1)
    max_jacobian = check.integer(f"{lm}.max_jacobian_elements", 1)
    inputs = len(check.get("curriculum.lateral_positions") or [])
    params = (inputs + 1) * hidden + hidden + 1  # eqs. (13)–(15): weights and biases
    if params > max_params:
        check.fail(
            "distance.hidden",
            hidden,
            f"gives {params} network parameters, more than distance.lm.max_params={max_params}",
        )
    if queue * params > max_jacobian:
        check.fail(
            "distance.queue_size",
            queue,
            f"× {params} parameters exceeds distance.lm.max_jacobian_elements={max_jacobian}",
        )

    check.choice("distance.input_scaling", INPUT_SCALINGS)
    held_out = 0.0
    for key in ("validation_fraction", "test_fraction"):
        held_out += check.number(f"distance.{key}", at_least=0, below=1)
    if held_out >= 1:
        check.fail(
            "distance.test_fraction",
            check.get("distance.test_fraction"),
            "and distance.validation_fraction must leave some of the queue to fit",
        )
    check.integer("distance.max_fail", 1, " (epochs)")
    check.choice("distance.estimator", ESTIMATORS)
    check.choice("distance.targets", sorted(TARGET_SOURCES))
    check.number("distance.odometry.walk_fraction", above=0, at_most=1)
    check.number("distance.odometry.nominal_stride_m", above=0, what=" (metres)")
    if check.get("distance.fit_from") is not None:
        fit_from = check.integer("distance.fit_from", 1)
        if fit_from > queue:
            check.fail(
                "distance.fit_from", fit_from, f"must be ≤ distance.queue_size={queue}, or null"
            )


def check_movement(check: Checks) -> None:
    route = check.choice("movement.route", ROUTES)
    check.number("movement.price_per_trial", at_least=0, what=" (percentage points per trial)")
    check.number("movement.price_per_cm", at_least=0, what=" (percentage points per cm)")
    check.number("movement.explore", above=0, at_most=1)
    if route == "planned":
        queue = check.get("distance.queue_size")
        if queue < 2:
            check.fail(
                "distance.queue_size",
                queue,
                "movement.route=planned needs at least 2 (its leave-one-out errors)",
            )
        check.require("env.robots", 1, "movement.route=planned needs 1")
        check.require(
            "distance.targets",
            "supervisor",
            "movement.route=planned learns from the supervisor's distances",
        )
        check.require(
            "curriculum.stages",
            None,
            "movement.route=planned plans over all of L: leave the stages null",
        )
