"""Sliding-window 2D lidar graph SLAM of Pham et al. §II-C, §III-B, §IV-B (numerical core).

* **Tracking**: every scan is matched by PLICP (Pham et al. eqs. 1-3) against the latest node's
scan,
  starting from the previous relative motion; the pose is the node's pose composed with it.
  A poor match (``correlative_trigger``; 0: every scan) is re-seeded by the branch-and-bound
  correlative search (Olson 2009, :mod:`correlative`) over ± ``search_linear_window`` /
  ± ``search_angular_window``, which wins if its likelihood is ``search_prior_margin`` higher
  (if the scans' stamps give the motion a time base; otherwise the higher likelihood wins).
  With ``field_refine_unconverged``, a PLICP refinement of the searched pose that does not
  converge competes with a Gauss-Newton ascent of the search's likelihood field (Hector's).
* **Nodes**: a new node when the match exceeds ``node_translation`` or ``node_rotation``. Its
  consecutive constraint (to the previous node) carries the Censi covariance (Pham et al. eqs. 4-10)
  — or, with ``landscape_temperature``, the spread of the tracking field's score around the
  match (Olson 2009 §III-C), which is wide where the scene leaves a direction free — and is
  robustified with Barron's kernel (Pham et al. eqs. 13-14, ``alpha``, ``c``); it is also
  densely linked (plain Gaussian) to the window's nodes within ``link_radius`` whose match
  converges with a small residual.
* **Optimisation**: Levenberg-Marquardt (gtsam, at most 100 iterations, as Pham et al. §V-A) over
the
  nodes of the sliding window; nodes outside it that constrain it are held fixed by tight priors,
  so the update time does not grow with the map.
* **Loops** (Pham et al. §II-C): a node whose index differs from an older node's by
``loop_index_gap``
  and lies within ``loop_radius`` of it is matched to it (from the graph's relative pose, with
  PLICP's rotation search); an accepted match adds a robustified loop constraint and marks the
  whole graph for optimisation, which :meth:`GraphSlam.optimise_pending` runs when the caller
  decides (its own slower event in ``LidarSlam2D``, so the per-scan update never stalls).
  For logs whose drift outgrows PLICP's basin (ours, not Pham et al.'s): ``loop_per_chain`` matches
  one node per earlier pass; ``loop_linear_window`` > 0 first searches the new node's recent scans
  against the candidate's neighbours by the correlative matcher and refuses fits that are weak
  (``min_loop_score``) or repeated elsewhere in the window (``max_loop_ambiguity``: corridors);
  ``loop_gnc`` makes loops Gaussian and lets each full optimisation reject inconsistent ones by
  graduated non-convexity (Yang et al. 2020, gtsam's GncLMOptimizer with the TLS loss; its μ
  moves by ``gnc_step`` per step). GNC cannot judge a loop that nothing else ties between two
  passes: with ``loop_confirm_nodes`` a loop joins the graph only once a second one between the
  same passes agrees with it (ORB-SLAM's temporal consistency, Mur-Artal et al. 2015).
* **Map** (Pham et al. §IV): a log-odds grid; a node's scan is inserted when the node is created and
  re-rendered (removed at its old pose, inserted at its new one) when optimisation moved it by
  more than ``rerender_translation`` / ``rerender_rotation``.

Everything is plain Python/numpy/gtsam state in one object, so a LeafSystem can keep it in the
Context and ``copy.deepcopy`` it.

The package's modules: :mod:`.config` (the configuration), :mod:`.poses` (planar pose
algebra), :mod:`.graph` (nodes and constraints), :mod:`.tracking`, :mod:`.odometry`,
:mod:`.loops`, :mod:`.relink` and :mod:`.optimisation` (the mixins of each job) and
:mod:`.core` (:class:`GraphSlam`, composing them); this module re-exports the names other
code imports.
"""

from usvdrake.systems.slam.graph_slam.config import GraphSlamConfig
from usvdrake.systems.slam.graph_slam.core import GraphSlam
from usvdrake.systems.slam.graph_slam.graph import Constraint, Node
from usvdrake.systems.slam.graph_slam.odometry import odometry_covariance
from usvdrake.systems.slam.graph_slam.poses import (
    between,
    body_pose,
    compose,
    compose_covariance,
    deskew_scan,
)

__all__ = [
    "Constraint",
    "GraphSlam",
    "GraphSlamConfig",
    "Node",
    "between",
    "body_pose",
    "compose",
    "compose_covariance",
    "deskew_scan",
    "odometry_covariance",
]
