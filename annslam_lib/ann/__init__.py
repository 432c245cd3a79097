"""The neural-network landmark model of section 4.2, made testable (notebook 07 "ANN landmarks").

What the paper says: a back-propagation network is "trained on the SLAM landmark equation
results and the true landmarks", and its output (the landmark position) is fed to the
EKF. Read literally, the network maps the inverse observation model's landmark to the
surveyed one. Here it learns the CORRECTION to that output, so that "no correction"
(the inverse model itself) is the baseline every number is compared with.

Training samples (:func:`training_set`)
    One per beacon observation the filter used (ObservationLog status 'associated' or
    'new': the first sighting initialises a landmark, where the paper uses the network
    too). Inputs, in the order of :data:`FEATURE_NAMES`:

    ====================  ================================================================
    pose_x, pose_y        the PRIOR laser pose (predicted, before the scan's update), m
    sin_phi, cos_phi      its heading as sin / cos (no jump at +-pi)
    range, bearing        the measurement z (m, rad 0..pi from the vehicle's right)
    sin_ray, cos_ray      direction of the ray in the world, phi + bearing - pi/2
    intensity             reflectivity level 0..4 (0 where the source has none)
    width                 cluster chord width or trunk diameter, m (0 where unknown,
                          e.g. the simulator's own detections)
    lm_x, lm_y            the inverse observation l = g(prior pose, z), m
    ====================  ================================================================

    Why the prior pose: the filter can only use the network BEFORE it updates with the
    scan, so at run time only the prior exists; and the posterior pose has already been
    corrected with this very measurement against the mapped landmark, so g(posterior, z)
    is pulled toward the map (which is close to the truth): training on it would leak
    the target into the input and score the network on information it cannot have.
    Target: the surveyed / true position of the beacon, Y = target - l.

Network and training (:func:`train`): an MLP (tanh hidden layers, linear output, default
one hidden layer of 10 neurons: MATLAB nntool's ``fitnet``), inputs and outputs
standardised with the TRAINING split's mean and standard deviation, trained full batch by
Levenberg-Marquardt (nntool's default ``trainlm``; the Jacobian by back-propagation) or
Adam, with nntool's early stopping: training stops after ``max_fail`` = 6 consecutive
epochs without a new best validation MSE, and the weights of the best epoch are kept.
Deterministic on CPU (seeded generator, deterministic algorithms, one thread).

Two evaluation protocols (:func:`evaluate_chronological`, :func:`evaluate_leave_beacons_out`):
with 15 beacons a network that sees its inputs' absolute positions can simply memorise
where the beacons are. A chronological split scores it on beacons it was trained on; the
leave-beacons-out split only on beacons it has never seen. The gap between the two is
the memorisation. Neither is leak-free: the chronological test scores beacons seen in
training; leave-beacons-out trains on the SAME scans (other beacons), so a network fed the
pose can learn the filter's pose error along the route at those times and apply it to the
held-out beacons of the same scans (on the Car Park that is the likely source of its small
gain: with the measurement features alone, or the pose alone, it gains nothing; notebook 07).

Use in the EKF (``slam.runner.run(dataset, config.replace(landmark_model='ann'),
landmark_model=model)``, notebook 08): the model turns each
detection z into a pseudo-measurement z' = h(prior pose, corrected landmark), with its own
noise (:attr:`TrainedModel.sigma_range`, ``sigma_bearing``, from validation residuals).
z' REPLACES z: the network's output is computed from z, so using both would count the
same measurement twice. :class:`InverseModel` is the identity model (z' = z).

What the per-observation RMSE hides: single observations are noisy (simulator: 0.34 m RMS
from 1 degree of bearing at up to 30 m), so a learned correction that is a few centimetres
wrong barely changes their RMSE (errors add in quadrature). But that error is a smooth
function of the geometry, nearly the same for every sighting of a beacon, and the filter,
which averages a hundred sightings per beacon, cannot average it away: the map can get
worse while the observation RMSE says "no change" (tests/test_ann.py, notebook 08).

Modules: ``samples`` (the training samples, splits), ``network`` (the MLP, training, the
chapter's references), ``io`` (safe save/load), ``evaluation`` (protocols, figures' data).
Everything is reachable from here (``ann.train``, ``ann.TrainingSet``...); torch is
imported only when a network is built.
"""
from __future__ import annotations

from .._lazy import attach

_WHERE = {
    "samples": ["FEATURE_NAMES", "MEASUREMENT_FEATURES", "USED_STATUS", "SPLITS",
                     "TrainingSet", "encode", "training_set", "Split", "chronological_split",
                     "beacon_folds", "time_fold_edges", "time_folds", "beacon_holdout_sizes"],
    "network": ["ALGORITHMS", "TrainConfig", "TrainedModel", "InverseModel", "train",
                "with_features", "forward", "train_loop", "mapminmax", "mapminmax_reverse",
                "one_torch_thread"],
    "io": ["UnsafeModelFile", "save", "load"],
    "evaluation": ["split_rmse", "Evaluation", "evaluate", "evaluate_chronological",
                   "evaluate_leave_beacons_out", "error_histogram", "regression",
                   "regression_line", "HiddenSizeGrid", "hidden_size_grid", "grid_summary"],
}
__getattr__, __dir__, __all__ = attach(__name__, list(_WHERE),
                                       {n: m for m, names in _WHERE.items() for n in names})
