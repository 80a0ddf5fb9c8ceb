"""The configuration of :class:`~usvdrake.systems.slam.graph_slam.GraphSlam`: the dataclass
:class:`GraphSlamConfig` with every threshold, window, noise model and map parameter of the
tracking, node creation, odometry, loop closure, relink, optimisation and map (their units
and sources in the comments beside them).
"""

from dataclasses import dataclass, field


@dataclass
class GraphSlamConfig:
    node_translation: float = 0.5  # [m] motion since the last node that makes a new node
    node_rotation: float = 0.17  # [rad] (~10°) likewise
    window: int = 15  # [nodes] optimised together on each new node
    link_radius: float = 4.0  # [m] dense links to window nodes within this distance
    max_link_residual: float = 0.15  # [m] RMS point-to-line error accepting a match (≥ noise)
    # a tracking match whose residual exceeds this many max_link_residual is re-seeded by a
    # correlative search (Olson 2009); lower = more robust to large motions, slower
    correlative_trigger: float = 2.0
    search_linear_window: float = 1.2  # [m] ± translation of that search about the guess
    search_angular_window: float = 0.7  # [rad] (~40°) ± rotation of that search
    search_from_rest: bool = False  # centre it on no motion (True) or constant velocity
    # the searched pose replaces PLICP's from the constant-velocity guess only if its
    # likelihood score is higher by this much: along a featureless corridor the two tie and
    # the motion model decides (Olson 2009's motion prior, as a margin). A scan stamped no
    # later than the previous one (a log with identical stamps) gives the motion no time
    # base to extrapolate over: there the higher score wins
    search_prior_margin: float = 0.02
    # [1/m²] the search's and that choice's scores lose this × the step's sideways motion²
    # (correlative.lateral_motion: 0 along any arc; for vehicles that cannot slide; 0: off)
    lateral_weight: float = 0.0
    refine_max_distance: float = 1.0  # [m] PLICP's pairing distance refining the search
    # PLICP's refinement of the search's pose that does not converge (it slid along a corridor,
    # or cycles) is set against a Gauss-Newton ascent of the search's own likelihood field from
    # that pose (Kohlbrecher 2011 eqs. 4-11, hector.match_scan); the higher score is kept
    field_refine_unconverged: bool = False
    search_resolution: float = 0.05  # [m] its grid (and the likelihood field's cells)
    search_sigma: float = 0.1  # [m] width of a reference point in the likelihood field
    min_link_points: int = 40  # correspondences a match needs
    trim: float = 0.9  # fraction of PLICP's pairs kept, least point-to-line error first
    # [m] RMS point-to-line error above which a tracking match failed (garbage, a blinded or
    # half-empty scan): the pose follows the constant-velocity guess and the scan never
    # becomes a node, so it cannot become the reference of the scans after it
    max_track_residual: float = 0.2
    # [-] a tracking match whose points' mean likelihood in the node's field (0-1) is below this
    # failed too, whatever its residual: PLICP's residual is over the pairs it kept, and a scan
    # that shows little of the node's scene (after a gap in the log) can pair a few points well
    # at a wrong pose (0: off)
    min_track_score: float = 0.0
    reanchor_after: int = 10  # [scans] failed in a row: the current scan becomes a node
    loop_index_gap: int = 40  # [nodes] index difference that makes a loop candidate
    loop_radius: float = 6.0  # [m] distance that makes a loop candidate
    max_loop_residual: float = 0.05  # [m] stricter acceptance for loops (a false loop is costly)
    min_loop_points: int = 100  # correspondences a loop match needs
    # [m] > 0: a loop candidate is first searched by the correlative matcher within this
    # window (and ± loop_angular_window) of the graph's relative pose, and kept only if its
    # likelihood score reaches min_loop_score; 0: PLICP's own rotation search (Pham et al.)
    loop_linear_window: float = 0.0
    loop_submap: int = 3  # [nodes] either side of a loop candidate (before the new node) matched
    # PLICP refines a searched loop against the candidate's submap (True) or its scan (False)
    loop_refine_submap: bool = False
    loop_robust: bool = True  # Barron-robustified loop constraints (False: Gaussian)
    # full optimisations reject outlier loops by GNC (TLS loss) instead of a robust kernel;
    # the loops' covariance gets this floor [m, m, rad] (what a correct loop may still be off)
    loop_gnc: bool = False
    # the factor GNC's μ moves by between its steps (gtsam's default 1.4): 3 took the four largest
    # full solves captured from raw Freiburg 079 from 1.1-1.9 s to 0.45-0.77 s, the same loops
    # rejected on 5 of the 6 captured
    gnc_step: float = 3.0
    loop_min_sigma: list[float] = field(default_factory=lambda: [0.03, 0.03, 0.01])
    loop_per_chain: bool = False  # match one node per pass near the new node, not every one
    # a loop joins the graph only once another, found within this many new nodes between
    # nearby nodes (≤ 50 apart) of the same two passes, agrees with it within
    # loop_confirm_tolerance [m, rad] (the place recognised twice: ORB-SLAM's temporal
    # consistency, Mur-Artal 2015 §VI-A); a loop nothing confirms is dropped. 0: each on its own
    loop_confirm_nodes: int = 0
    loop_confirm_tolerance: list[float] = field(default_factory=lambda: [0.2, 0.05])
    # [m] a new node looks for loops only once the graph has gone this far (or turned 1 rad)
    # since the last node that looked (0: every node; for logs dense in nodes; ours)
    loop_spacing: float = 0.0
    loop_max_chains: int = 8  # [-] passes matched per new node, nearest first
    loop_angular_window: float = 0.5  # [rad]
    loop_distinct: float = 0.5  # [m] a runner-up pose this far from the best is a rival
    max_loop_ambiguity: float = 0.9  # [-] rival score / best score above which a loop is refused
    # [m] > 0: a searched loop's pose is searched again for the new node's scan alone, within
    # this window (and ± loop_rematch_angle [rad]) of the pose the recent scans found: those sit
    # where tracking put them relative to the new node, and one wrong step there moves the
    # whole query with it (ours; 0: the recent scans' pose is refined as it is)
    loop_rematch_window: float = 0.0
    loop_rematch_angle: float = 0.1
    min_loop_score: float = 0.5  # [-] mean likelihood of the loop scan's points, in [0, 1]
    # [m] > 0: after the last scan (GraphSlam.relink, offline), every node is matched by PLICP
    # from the final estimate to the older nodes within this radius (index gap ≥ 2; at most
    # relink_max_links of them, spread over their indices; 0: all), a match moving less than
    # relink_max_correction [m] from it, scoring min_loop_score and passing the link checks is
    # added as a loop (GNC candidate, tracking covariance), and the whole graph is optimised
    # once more (ours, not Pham et al.'s)
    relink_radius: float = 0.0
    relink_max_links: int = 0
    relink_max_correction: float = 0.3
    alpha: float = 0.0  # Barron α of the robustified constraints (0: Cauchy)
    c: float = 1.0  # Barron scale c (in units of the whitened error)
    range_sigma: float = 0.02  # [m] range noise for the Censi covariance
    # > 0: consecutive constraints take the spread of the tracking field's score around the
    # match at this temperature (Olson 2009 §III-C, correlative.match_covariance) above the
    # min_sigma floor, instead of Censi's closed form, which stays centimetre-small along a
    # corridor (ours, not Pham et al.'s; 0: Censi's)
    landscape_temperature: float = 0.0
    min_sigma: list[float] = field(default_factory=lambda: [0.01, 0.01, 0.005])  # [m, m, rad] floor
    # Wheel odometry, when the scans come with it (GraphSlam.process's ``odometry``; ours, not
    # Pham et al.'s, which has none). It ties a node to the node where the odometry had gone
    # odometry_span [m] (or 1 rad) before, a robust constraint
    # with a random walk's covariance of [m/√m travelled, rad/√rad turned, rad/√m travelled]
    # (odometry_covariance): along a corridor, where the scans do not measure the motion, it
    # does. A span, not every step: logged odometry drops out and catches up (raw MIT-CSAIL
    # reads no motion for 4 scans while the robot moved 0.65 m, then a 0.34 m step for 0.22 m)
    odometry_sigma: list[float] = field(default_factory=lambda: [0.05, 0.3, 0.05])
    odometry_span: float = 1.0
    # an odometry constraint is left out when it disagrees with the scans' own chain of
    # steps over its span: χ² of the difference under both covariances above this (3 dof,
    # 16.27: p = 0.001). Raw Freiburg 079's logged odometry has gross errors while the robot
    # manoeuvres (a 2.2 m forward step where the scans and the corrected poses back up 2.3 m):
    # robustified only, they took its ATE from 0.09 to 1.3 m over the first 1800 scans.
    # Along a corridor the chain's covariance is long, the gate wide: the odometry stays (if
    # the tracking did not settle on a wrong step there: odometry_seed)
    odometry_gate: float = 16.27
    # odometry also seeds a second tracking match beside the constant velocity's, kept unless
    # that one scores search_prior_margin higher. Along a corridor the constant velocity feeds
    # on itself: once a step came out short, the next match starts from a short step and the
    # flat corridor keeps it there (raw ACES's first corridor: 2.1 m driven, 0.2 m tracked,
    # the odometry's span then gated out). Measured on the CARMEN logs only, so LOG_CONFIG
    # sets it (usvdrake.run.slam2d) and the other configurations keep it off
    odometry_seed: bool = False
    # [m, rad] > 0: a scan with an odometry step is searched within ± these of the
    # odometry's guess instead of search_*_window about rest or the constant velocity (the
    # wheels say roughly where the scan is: a small window, not ±1.5 m / ±92° every scan; ours)
    odometry_search_window: list[float] = field(default_factory=lambda: [0.0, 0.0])
    # the odometry's distance and turn are scaled by what the scans measured where they could
    # (GraphSlam.odometry_scale): steps whose tracking σ along the motion is within this [m]
    odometry_calibrate: bool = True
    odometry_calibration_sigma: float = 0.02
    max_iterations: int = 100  # LM steps (Pham et al. §V-A)
    # the full optimisations a loop asks for run in a worker process (Pham et al.: its own thread),
    # started and merged by the caller's slower event (GraphSlam.background); False: inline
    full_in_worker: bool = True
    # De-skew each scan to its last beam with the last scan-to-scan motion as a constant
    # twist, when the scan says its beams fired over time (``LaserScan.time_increment`` > 0).
    # Ours, not Pham et al.'s: on valley_survey the sweep's own motion biased the matches while
    # turning (180 s: online ATE 0.153 m with the motion simulated, 0.052 m without).
    deskew: bool = True
    map_resolution: float = 0.2  # [m] online map (Pham et al. §V-B: 0.4 m in the valley)
    map_origin: list[float] = field(default_factory=lambda: [-150.0, -150.0])  # [m]
    map_size: list[float] = field(default_factory=lambda: [300.0, 300.0])  # [m] width, height
    max_range: float = 30.0  # [m] beyond this a beam counts as no return for the map
    # each node's scan rendered into the log-odds map as it comes, the moved ones re-rendered
    # after each optimisation (a LeafSystem's map port reads it at any time); False: nothing is
    # rendered until ``GraphSlam.render_map`` renders every node at its final pose (offline
    # runs: the map was a fifth of raw MIT-CSAIL's time, and nothing reads it before the end)
    live_map: bool = True
    rerender_translation: float = 0.05  # [m]
    rerender_rotation: float = 0.01  # [rad]
