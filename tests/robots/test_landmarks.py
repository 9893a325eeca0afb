"""Landmark post detection on synthetic scans, the sensor model and data association."""

import math

import numpy as np
import pytest
import shapely

from robots import landmarks as landmarks_module
from robots.landmarks import (
    CHI2_2DOF_99,
    LandmarkObservation,
    associate_landmarks,
    detect_landmarks,
    mahalanobis_matrix,
    range_bearing_model,
)
from semistatic.frames import compose, transform_points, wrap_angle
from semistatic.types import Scan

POST_RADIUS = 0.04
POST_REMISSION = 0.95
WALL_REMISSION = 0.3
LMS100_ANGLES = np.radians(np.arange(-135.0, 135.0 + 1e-9, 0.5))
ROOM = [
    ((-10.0, -6.0), (10.0, -6.0)),
    ((10.0, -6.0), (10.0, 6.0)),
    ((10.0, 6.0), (-10.0, 6.0)),
    ((-10.0, 6.0), (-10.0, -6.0)),
]


def cast_scan(
    sensor_pose,
    posts,
    walls,
    *,
    angles=LMS100_ANGLES,
    range_sigma=0.0,
    intensity_sigma=0.03,
    rng=None,
    range_max=20.0,
    radius=POST_RADIUS,
    reflective_walls=(),
):
    """Ray-cast a scan against circles (posts) and segments (walls), pure numpy."""
    rng = np.random.default_rng(0) if rng is None else rng
    x, y, theta = sensor_pose
    directions = np.column_stack([np.cos(angles + theta), np.sin(angles + theta)])
    origin = np.array([x, y])
    best = np.full(angles.size, np.inf)
    remission = np.zeros(angles.size)
    for centre in np.asarray(posts, dtype=float).reshape(-1, 2):
        offset = centre - origin
        along = directions @ offset
        disc = along**2 - (offset @ offset - radius**2)
        t = np.where(disc >= 0.0, along - np.sqrt(np.maximum(disc, 0.0)), np.inf)
        t = np.where(t > 0.0, t, np.inf)
        closer = t < best
        best[closer], remission[closer] = t[closer], POST_REMISSION
    tagged = [(w, WALL_REMISSION) for w in walls] + [(w, POST_REMISSION) for w in reflective_walls]
    for (start, end), wall_remission in tagged:
        start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
        edge, rel = end - start, start - origin
        denominator = directions[:, 0] * edge[1] - directions[:, 1] * edge[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (rel[0] * edge[1] - rel[1] * edge[0]) / denominator
            u = (rel[0] * directions[:, 1] - rel[1] * directions[:, 0]) / denominator
        hit = (np.abs(denominator) > 1e-12) & (t > 0.0) & (u >= 0.0) & (u <= 1.0)
        t = np.where(hit, t, np.inf)
        closer = t < best
        best[closer], remission[closer] = t[closer], wall_remission
    ranges = best + rng.normal(0.0, range_sigma, angles.size) if range_sigma else best.copy()
    ranges[best > range_max] = np.inf
    intensities = remission + rng.normal(0.0, intensity_sigma, angles.size)
    return Scan(
        ranges=ranges,
        angle_min=angles[0],
        angle_increment=angles[1] - angles[0],
        intensities=intensities,
        range_max=range_max,
        pose=sensor_pose,
    )


def fully_visible(sensor_pose, posts, scan, index, *, radius=POST_RADIUS):
    """True when post ``index`` is hit by a beam, inside the field of view, not occluded."""
    centre = np.asarray(posts[index], dtype=float)
    rel = centre - np.asarray(sensor_pose[:2])
    distance = float(np.hypot(*rel))
    bearing = wrap_angle(math.atan2(rel[1], rel[0]) - sensor_pose[2])
    half_width = math.asin(radius / distance)
    angles = scan.angles()
    if not (angles[0] < bearing - half_width and bearing + half_width < angles[-1]):
        return False
    silhouette = np.abs(wrap_angle(angles - bearing)) <= half_width + scan.angle_increment
    if not np.any(np.abs(wrap_angle(angles - bearing)) < half_width):
        return False  # falls between two beams
    # Unoccluded: every beam across the silhouette and its neighbours returns no nearer
    # than the post's near surface (walls and posts further away are fine).
    return bool(np.all(scan.ranges[silhouette] > distance - radius - 0.05))


def random_scene(rng, num_posts=6):
    posts = rng.uniform([-9.0, -5.0], [9.0, 5.0], (num_posts, 2))
    pose = np.array([*rng.uniform([-8.0, -4.0], [8.0, 4.0]), rng.uniform(-np.pi, np.pi)])
    return posts, pose


def centre_errors(observations, posts, sensor_pose):
    """For each observation: (index of the nearest true post, distance to it)."""
    points = np.array([obs.point() for obs in observations]).reshape(-1, 2)
    world = transform_points(sensor_pose, points)
    gaps = np.linalg.norm(world[:, None, :] - np.asarray(posts)[None, :, :], axis=-1)
    nearest = gaps.argmin(axis=1) if len(observations) else np.zeros(0, dtype=int)
    return nearest, gaps[np.arange(len(observations)), nearest]


# ---------------------------------------------------------------- acceptance: detection


@pytest.mark.parametrize(
    ("range_sigma", "detection_range"),
    [(0.0, 6.0), (0.005, 5.0)],
    ids=["noise-free-ranges-6m", "5mm-noise-5m"],
)
def test_every_post_in_range_is_detected_within_2cm_and_nothing_else(range_sigma, detection_range):
    rng = np.random.default_rng(42)
    worst, checked = 0.0, 0
    for _ in range(60):
        posts, pose = random_scene(rng)
        scan = cast_scan(pose, posts, ROOM, range_sigma=range_sigma, rng=rng)
        observations = detect_landmarks(scan, range_sigma=max(range_sigma, 1e-3))
        nearest, errors = centre_errors(observations, posts, pose)
        # Nothing else: every detection is a real post (no wall, corner or noise).
        assert np.all(errors < 0.1), errors
        assert len(set(nearest.tolist())) == len(observations)
        for index in range(len(posts)):
            distance = np.hypot(*(posts[index] - pose[:2]))
            if distance > detection_range or not fully_visible(pose, posts, scan, index):
                continue
            matches = errors[nearest == index]
            assert matches.size == 1, f"post {index} at {distance:.2f} m not detected"
            worst = max(worst, float(matches[0]))
            checked += 1
    assert checked > 80
    assert worst <= 0.02, f"worst centre error {worst * 100:.2f} cm"


def test_centre_estimate_beats_naive_and_covariance_is_consistent_at_lms100_noise():
    """At the LMS100's 12 mm range noise, 0.5 deg: statistics within 6 m."""
    rng = np.random.default_rng(7)
    ours, naive, nis = [], [], []
    for _ in range(150):
        posts, pose = random_scene(rng)
        scan = cast_scan(pose, posts, ROOM, range_sigma=0.012, rng=rng)
        observations = detect_landmarks(scan, range_sigma=0.012)
        nearest, errors = centre_errors(observations, posts, pose)
        for obs, index, error in zip(observations, nearest, errors, strict=True):
            rel = posts[index] - pose[:2]
            if np.hypot(*rel) > 6.0:
                continue
            ours.append(error)
            beams = obs.beam_indices
            bearing = scan.angles()[beams].mean()
            distance = scan.ranges[beams].min() + POST_RADIUS
            naive_point = distance * np.array([np.cos(bearing), np.sin(bearing)])
            naive.append(np.linalg.norm(transform_points(pose, naive_point)[0] - posts[index]))
            true_range = np.hypot(*rel)
            true_bearing = wrap_angle(math.atan2(rel[1], rel[0]) - pose[2])
            innovation = np.array([obs.range - true_range, wrap_angle(obs.bearing - true_bearing)])
            nis.append(innovation @ np.linalg.solve(obs.covariance, innovation))
    ours, naive = np.array(ours), np.array(naive)
    assert ours.size > 200
    assert np.percentile(ours, 95) <= 0.022
    assert ours.mean() < 0.85 * naive.mean()
    # Mean NIS of a 2-dof Gaussian is 2: the reported covariance is honest.
    assert 1.4 <= np.mean(nis) <= 2.6


# ---------------------------------------------------------------- detection: special cases


def test_walls_alone_give_nothing():
    scan = cast_scan((0.0, 0.0, 0.3), [], ROOM)
    assert detect_landmarks(scan) == []


def test_reflective_strip_on_a_wall_is_not_a_post():
    strip = [((3.0, -0.5), (3.0, 0.5))]
    scan = cast_scan((0.0, 0.0, 0.0), [(2.0, 2.0)], ROOM, reflective_walls=strip)
    observations = detect_landmarks(scan)
    assert len(observations) == 1
    np.testing.assert_allclose(
        transform_points(scan.pose, observations[0].point())[0], [2.0, 2.0], atol=0.02
    )


def test_two_posts_overlapping_in_angle_are_split_and_the_occluded_one_dropped():
    # The far post peeks out beside the near one: two bright runs touch in angle.
    posts = [(2.0, 0.0), (5.0, 0.1)]
    scan = cast_scan((0.0, 0.0, 0.0), posts, ROOM)
    observations = detect_landmarks(scan)
    nearest, errors = centre_errors(observations, posts, scan.pose)
    assert nearest.tolist() == [0]
    assert errors[0] < 0.005


def test_post_cut_by_the_field_of_view_is_ignored():
    angles = np.radians(np.arange(-10.0, 10.0 + 1e-9, 0.5))
    scan = cast_scan(
        (0.0, 0.0, 0.0),
        [(3.0 * np.cos(np.radians(10.3)), 3.0 * np.sin(np.radians(10.3)))],
        ROOM,
        angles=angles,
    )
    assert scan.intensities[-1] > 0.7  # the last beam does hit the post
    assert detect_landmarks(scan) == []


def test_posts_behind_dropouts_and_noise_are_still_found():
    rng = np.random.default_rng(3)
    posts = [(3.0, 1.0), (-2.0, 3.0), (4.0, -3.0)]
    scan = cast_scan((0.0, 0.0, 0.2), posts, ROOM, range_sigma=0.005, rng=rng)
    ranges = scan.ranges.copy()
    ranges[::7] = np.inf  # dropouts away from the posts do not matter
    hit = np.flatnonzero(scan.intensities > 0.7)
    ranges[hit] = scan.ranges[hit]
    noisy = Scan(
        ranges=ranges,
        angle_min=scan.angle_min,
        angle_increment=scan.angle_increment,
        intensities=scan.intensities,
        range_max=scan.range_max,
        pose=scan.pose,
    )
    nearest, errors = centre_errors(detect_landmarks(noisy), posts, scan.pose)
    assert sorted(nearest.tolist()) == [0, 1, 2]
    assert np.all(errors < 0.03)


@pytest.mark.parametrize(
    "ranges",
    [[], [np.inf] * 5, [np.nan] * 5, [1.0, np.inf, np.nan, 2.0, 3.0]],
    ids=["empty", "all-inf", "all-nan", "mixed-invalid"],
)
def test_degenerate_scans_give_no_posts(ranges):
    scan = Scan(
        ranges=ranges,
        angle_min=-0.1,
        angle_increment=0.01,
        intensities=np.full(len(ranges), 0.99),
        range_max=10.0,
    )
    observations = detect_landmarks(scan)
    # Invalid readings never form posts; the only valid bright runs here touch the edges
    # of the field of view or are far too wide for a 4 cm post.
    assert observations == []


def test_scan_without_intensities_is_refused_with_a_helpful_message():
    scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.01)
    with pytest.raises(ValueError, match="intensities"):
        detect_landmarks(scan)


def test_bad_parameters_are_refused():
    scan = cast_scan((0.0, 0.0, 0.0), [], ROOM)
    with pytest.raises(ValueError, match="post_radius"):
        detect_landmarks(scan, post_radius=0.0)
    with pytest.raises(ValueError, match="range_sigma"):
        detect_landmarks(scan, range_sigma=-1.0)


def test_observation_validates_its_covariance_and_range():
    with pytest.raises(ValueError, match="2x2"):
        LandmarkObservation(1.0, 0.0, np.eye(3), [0])
    with pytest.raises(ValueError, match="range"):
        LandmarkObservation(-1.0, 0.0, np.eye(2), [0])
    obs = LandmarkObservation(1.0, 3 * np.pi / 2, np.eye(2), [0])
    assert obs.bearing == pytest.approx(-np.pi / 2)
    with pytest.raises(ValueError, match="read-only"):
        obs.covariance[0, 0] = 5.0


# ---------------------------------------------------------------- sensor model


@pytest.mark.parametrize("mount", [(0.0, 0.0, 0.0), (0.3, -0.1, 0.2), (-0.2, 0.15, -3.0)])
def test_range_bearing_model_matches_geometry_and_numeric_jacobian(mount):
    rng = np.random.default_rng(11)
    pose = np.array([1.0, -2.0, 2.9])
    landmarks = rng.uniform(-6.0, 6.0, (8, 2))
    predicted, jacobians = range_bearing_model(pose, landmarks, mount)
    sensor = compose(pose, mount)
    rel = landmarks - sensor[:2]
    np.testing.assert_allclose(predicted[:, 0], np.hypot(rel[:, 0], rel[:, 1]), atol=1e-12)
    np.testing.assert_allclose(
        predicted[:, 1], wrap_angle(np.arctan2(rel[:, 1], rel[:, 0]) - sensor[2]), atol=1e-12
    )
    step = 1e-6
    for axis in range(3):
        delta = np.zeros(3)
        delta[axis] = step
        plus, _ = range_bearing_model(pose + delta, landmarks, mount)
        minus, _ = range_bearing_model(pose - delta, landmarks, mount)
        numeric = (plus - minus) / (2 * step)
        numeric[:, 1] = wrap_angle(plus[:, 1] - minus[:, 1]) / (2 * step)
        np.testing.assert_allclose(jacobians[:, :, axis], numeric, atol=1e-6)


# ---------------------------------------------------------------- association


def observe(pose, landmarks, mount=(0.0, 0.0, 0.0), sigma=(0.01, 0.002)):
    predicted, _ = range_bearing_model(pose, landmarks, mount)
    covariance = np.diag(np.square(sigma))
    return [LandmarkObservation(r, b, covariance, [i]) for i, (r, b) in enumerate(predicted)]


def test_association_recovers_the_true_pairs_with_a_mount_offset():
    landmarks = np.array([[5.0, 0.0], [0.0, 5.0], [-5.0, 1.0], [3.0, -4.0]])
    mount = (0.4, 0.1, 0.05)
    pose = np.array([0.5, 0.2, 0.7])
    observations = observe(pose, landmarks[[2, 0, 3]], mount)
    pairs = associate_landmarks(
        observations,
        landmarks,
        pose + np.array([0.03, -0.02, 0.01]),
        np.diag([0.05**2, 0.05**2, 0.02**2]),
        mount,
    )
    assert pairs == [(0, 2), (1, 0), (2, 3)]


def test_association_ignoring_the_mount_fails_the_gate():
    landmarks = np.array([[5.0, 0.0], [0.0, 5.0]])
    mount = (0.6, 0.0, 0.3)
    pose = np.array([0.0, 0.0, 0.0])
    observations = observe(pose, landmarks, mount, sigma=(0.005, 0.001))
    cov = np.diag([1e-4, 1e-4, 1e-5])
    assert associate_landmarks(observations, landmarks, pose, cov, mount) == [(0, 0), (1, 1)]
    assert associate_landmarks(observations, landmarks, pose, cov) == []


def test_two_landmarks_inside_one_gate_are_ambiguous_and_skipped():
    landmarks = np.array([[5.0, 0.0], [5.0, 0.06], [0.0, 5.0]])
    observations = observe(np.zeros(3), landmarks[[0, 2]])
    cov = np.diag([0.05**2, 0.05**2, 0.01**2])
    pairs = associate_landmarks(observations, landmarks, np.zeros(3), cov)
    assert pairs == [(1, 2)]


def test_two_observations_claiming_one_landmark_are_both_skipped():
    landmarks = np.array([[5.0, 0.0], [0.0, 5.0]])
    observations = observe(np.zeros(3), landmarks) + observe(np.zeros(3), [[5.0, 0.05]])
    pairs = associate_landmarks(observations, landmarks, np.zeros(3), np.diag([1e-3] * 3))
    assert pairs == [(1, 1)]


def test_gate_wraps_bearings_across_pi():
    landmarks = np.array([[-5.0, 0.001], [5.0, 0.0]])
    obs = LandmarkObservation(5.0, -np.pi + 0.0005, np.diag([1e-4, 1e-5]), [0])
    distances = mahalanobis_matrix(
        [obs], *range_bearing_model(np.zeros(3), landmarks), np.zeros((3, 3))
    )
    assert distances[0, 0] < 1.0
    assert associate_landmarks([obs], landmarks, np.zeros(3), np.zeros((3, 3))) == [(0, 0)]


def test_gate_follows_the_chi_square_quantile():
    obs = LandmarkObservation(5.0, 0.0, np.diag([0.01**2, 1e-8]), [0])
    inside = np.array([[5.0 + 0.0300, 0.0]])  # 3.00 sigma: d2 = 9.00 < 9.21
    outside = np.array([[5.0 + 0.0305, 0.0]])  # 3.05 sigma: d2 = 9.30 > 9.21
    cov = np.zeros((3, 3))
    assert associate_landmarks([obs], inside, np.zeros(3), cov, gate=CHI2_2DOF_99) == [(0, 0)]
    assert associate_landmarks([obs], outside, np.zeros(3), cov, gate=CHI2_2DOF_99) == []


def test_association_of_nothing_is_empty():
    assert associate_landmarks([], [[1.0, 0.0]], np.zeros(3), np.eye(3)) == []
    obs = observe(np.zeros(3), [[1.0, 0.0]])
    assert associate_landmarks(obs, np.zeros((0, 2)), np.zeros(3), np.eye(3)) == []


# ---------------------------------------------------- detection against GEOS and by hand
#
# Which beams hit which post is GEOS's answer (shapely rays against the posts' circles and
# the walls), not cast_scan's; where a post is is known. Noise-free ranges let the
# centre estimate lock onto the true centre; a one-beam post is computed by hand.


def post_beams(sensor_pose, posts, walls, angles=LMS100_ANGLES, range_max=20.0):
    """Return, per post, the beams whose ray meets that post before anything else (GEOS)."""
    x, y, theta = sensor_pose
    ends = np.column_stack(
        [x + range_max * np.cos(angles + theta), y + range_max * np.sin(angles + theta)]
    )
    rays = shapely.linestrings(np.stack([np.broadcast_to([x, y], ends.shape), ends], axis=1))
    origin = shapely.Point(x, y)
    # 1024-gons: within 2e-7 m of the circle, far below any beam's miss distance here.
    circles = [shapely.Point(p).buffer(POST_RADIUS, quad_segs=256) for p in posts]
    obstacles = circles + [shapely.LineString(wall) for wall in walls]
    distances = np.full((len(obstacles), angles.size), np.inf)
    for row, obstacle in enumerate(obstacles):
        shapely.prepare(obstacle)
        meets = np.flatnonzero(shapely.intersects(obstacle, rays))
        hits = shapely.intersection(rays[meets], obstacle)
        distances[row, meets] = shapely.distance(origin, hits)
    first = np.argmin(distances, axis=0)
    hit = np.isfinite(distances.min(axis=0))
    return [np.flatnonzero(hit & (first == index)) for index in range(len(posts))]


def true_range_bearing(sensor_pose, post):
    rel = np.asarray(post, dtype=float) - np.asarray(sensor_pose[:2])
    return float(np.hypot(*rel)), wrap_angle(math.atan2(rel[1], rel[0]) - sensor_pose[2])


def scenes(rng, count, range_sigma):
    """Random rooms of 8 posts: (scan, posts, sensor pose)."""
    for _ in range(count):
        posts, pose = random_scene(rng, num_posts=8)
        yield cast_scan(pose, posts, ROOM, range_sigma=range_sigma, rng=rng), posts, pose


@pytest.mark.parametrize("range_sigma", [0.0, 0.005, 0.012])
def test_each_post_takes_exactly_the_beams_geos_says_hit_it(range_sigma):
    rng = np.random.default_rng(42)
    checked = 0
    for scan, posts, pose in scenes(rng, 25, range_sigma):
        beams = post_beams(pose, posts, ROOM)
        for kwargs in ({"range_sigma": max(range_sigma, 1e-3)}, {"range_sigma": 0.0}):
            observations = detect_landmarks(scan, **kwargs)
            nearest, errors = centre_errors(observations, posts, pose)
            assert np.all(errors < 0.1)
            for obs, index in zip(observations, nearest, strict=True):
                np.testing.assert_array_equal(obs.beam_indices, beams[index])
                checked += 1
    assert checked > 100


def test_noise_free_posts_are_located_at_their_centre():
    # Precise ranges: the bearing likelihood locks onto the centre, the range follows.
    # A post hit by one beam only is placed within its feasible interval (below).
    rng = np.random.default_rng(42)
    checked = 0
    for scan, posts, pose in scenes(rng, 40, 0.0):
        observations = detect_landmarks(scan, range_sigma=0.0)
        nearest, _ = centre_errors(observations, posts, pose)
        for obs, index in zip(observations, nearest, strict=True):
            true_range, true_bearing = true_range_bearing(pose, posts[index])
            bearing_error = abs(wrap_angle(obs.bearing - true_bearing))
            if obs.beam_indices.size == 1:
                # Somewhere in the interval the beam and its neighbours allow.
                assert bearing_error <= scan.angle_increment
                assert abs(obs.range - true_range) <= POST_RADIUS
                continue
            # Measured: 4e-5 m and 6.5e-4 m across (two beams), less with more beams.
            assert abs(obs.range - true_range) < 1e-4
            assert bearing_error * true_range < 1e-3
            checked += 1
    assert checked > 100


@pytest.mark.parametrize(("range_sigma", "bearing_sigma"), [(0.0, 0.0), (0.012, 1e-3)])
def test_one_beam_post_by_hand(range_sigma, bearing_sigma):
    # A post 8 m straight ahead hit by the middle beam only (its half-width asin(R / 8)
    # is 0.29 deg, the beams 0.5 deg apart). The centre bearing may lie where the beam
    # hits and both neighbours miss: [step - w, w - step] around 0 with w the
    # half-width, a uniform prior over 41 equally spaced candidates that all fit the one
    # range exactly: mean 0, variance width^2 (K + 1) / (12 (K - 1)). The range is the
    # hit plus the radius, with the beam's own variance; no coupling at the centre.
    step = math.radians(0.5)
    angles = step * np.arange(-20, 21)
    ranges, intensities = np.full(angles.size, 12.0), np.full(angles.size, 0.2)
    ranges[20], intensities[20] = 8.0 - POST_RADIUS, 0.95
    scan = Scan(ranges=ranges, angle_min=angles[0], angle_increment=step,
                intensities=intensities)
    [obs] = detect_landmarks(
        scan, post_radius=POST_RADIUS, range_sigma=range_sigma, bearing_sigma=bearing_sigma
    )
    half_width = math.asin(POST_RADIUS / 8.0)
    width = 2.0 * (step - half_width)
    candidates = 41
    bearing_variance = width**2 * (candidates + 1) / (12 * (candidates - 1)) + bearing_sigma**2
    assert obs.range == pytest.approx(8.0, abs=1e-12)
    assert obs.bearing == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(
        obs.covariance,
        [[range_sigma**2, 0.0], [0.0, bearing_variance]],
        rtol=1e-9,
        atol=1e-15,  # the mean lands within 1e-14 rad of 0: a 1e-19 coupling, no more
    )
    assert obs.beam_indices.tolist() == [20]


def test_min_beams_drops_the_posts_with_fewer_beams():
    posts = [(8.0, 0.0), (3.0, 1.0), (1.0, -1.0)]
    scan = cast_scan((0.0, 0.0, 0.0), posts, ROOM)
    counts = [beams.size for beams in post_beams((0.0, 0.0, 0.0), posts, ROOM)]
    assert counts[0] == 1 < counts[1] < counts[2]
    for min_beams in (1, counts[1], counts[1] + 1, counts[2], counts[2] + 1):
        found = detect_landmarks(scan, min_beams=min_beams, range_sigma=0.0)
        nearest, errors = centre_errors(found, posts, scan.pose)
        assert sorted(nearest.tolist()) == [k for k in range(3) if counts[k] >= min_beams]
        assert np.all(errors < 0.05)


def test_posts_in_one_scan_are_estimated_as_if_alone():
    # One scan, groups of very different sizes (a post at arm's length covers ~20 beams
    # beside far ones with 1-2) estimated in one batch: each post's estimate is the one
    # it gets alone in the scan, and near its true centre.
    posts = [(0.3, 0.0), (6.0, 2.0), (8.0, -3.0), (2.5, -2.0)]
    together = detect_landmarks(cast_scan((0.0, 0.0, 0.0), posts, ROOM), range_sigma=0.0)
    nearest, _ = centre_errors(together, posts, (0.0, 0.0, 0.0))
    assert sorted(nearest.tolist()) == [0, 1, 2, 3]
    sizes = sorted(obs.beam_indices.size for obs in together)
    assert sizes[0] <= 2
    assert sizes[-1] >= 15
    for obs, index in zip(together, nearest, strict=True):
        [alone] = detect_landmarks(
            cast_scan((0.0, 0.0, 0.0), [posts[index]], ROOM), range_sigma=0.0
        )
        np.testing.assert_array_equal(obs.beam_indices, alone.beam_indices)
        assert obs.range == pytest.approx(alone.range, rel=1e-12)
        assert obs.bearing == pytest.approx(alone.bearing, rel=0, abs=1e-12)
        np.testing.assert_allclose(obs.covariance, alone.covariance, rtol=1e-9, atol=1e-24)


def circle_hits(distance, bearing, offsets):
    """Return the near-side ranges of beams at ``bearing + offsets`` on a post (closed form)."""
    along, across = distance * np.cos(offsets), distance * np.sin(offsets)
    return along - np.sqrt(POST_RADIUS**2 - across**2)


def test_compiled_passes_on_ragged_groups_find_the_true_centres():
    # Groups of 1 to 17 beams in one batch (padding), fed to the compiled passes directly
    # (one numpy exp between them, as the detector does), with exact ranges of known
    # posts and the precise-range likelihood: every multi-beam group finds its centre; a
    # forced empty interval gives its point and only the beams' own bearing variance.
    rng = np.random.default_rng(9)
    sizes = [1, 3, 17, 6, 2]
    centres, hit_ranges, hit_angles = [], [], []
    for size in sizes:
        distance = rng.uniform(0.5, 6.0)
        half_width = math.asin(POST_RADIUS / distance)
        step = 1.8 * half_width / max(size, 2)
        offsets = step * (np.arange(size) - (size - 1) / 2) + rng.uniform(-0.2, 0.2) * step
        bearing = rng.uniform(-2.0, 2.0)
        centres.append((distance, bearing))
        hit_angles.append(bearing + offsets)
        hit_ranges.append(circle_hits(distance, bearing, offsets))
    ranges, angles = np.concatenate(hit_ranges), np.concatenate(hit_angles)
    # Read-only, as a Scan's arrays: the kernels' compiled version for scans serves.
    ranges.flags.writeable = angles.flags.writeable = False
    firsts = np.cumsum([0, *sizes[:-1]]).astype(np.int64)
    counts = np.array(sizes, dtype=np.int64)
    firsts_angle = np.array([group[0] for group in hit_angles])
    lasts_angle = np.array([group[-1] for group in hit_angles])
    # Misses far outside, so the interval is the hits' own ([last - w, first + w]) ...
    distance = np.array([group.min() + POST_RADIUS for group in hit_ranges])
    floor = 1e-4  # the likelihood sigma of precise ranges (_RANGE_SIGMA_FLOOR)
    lows, highs, candidates, exponents = landmarks_module._bearing_exponents(
        ranges, angles, firsts, counts, firsts_angle, lasts_angle, firsts_angle - 1.0,
        lasts_angle + 1.0, distance, POST_RADIUS, POST_RADIUS**2, floor**2,
    )
    # ... except group 3, whose interval is forced to a point.
    lows[3] = highs[3]
    candidates[3] = highs[3]
    distance, range_variance, cross, bearing, bearing_variance = (
        landmarks_module._centre_estimates(
            ranges, angles, firsts, counts, lows, highs, candidates, np.exp(exponents),
            POST_RADIUS**2, (0.05 * POST_RADIUS) ** 2, 0.0, 1e-6, True,
        )
    )
    for row, (true_distance, true_bearing) in enumerate(centres):
        assert lows[row] <= true_bearing <= highs[row] or row == 3
        if sizes[row] > 1 and row != 3:
            # To the candidate grid: within half a step of it.
            grid_step = (highs[row] - lows[row]) / (candidates.shape[1] - 1)
            assert bearing[row] == pytest.approx(true_bearing, abs=0.5 * grid_step)
            assert distance[row] == pytest.approx(true_distance, abs=1e-4)
        assert range_variance[row] >= 0.0
        assert range_variance[row] * bearing_variance[row] >= cross[row] ** 2
    assert bearing_variance[3] == 1e-6
    assert bearing[3] == lows[3]


@pytest.mark.parametrize("count", [1, 2, 7, 8, 9, 16, 17, 41, 45])
def test_sums_follow_numpy_order_to_the_bit(count):
    # The detector's sums reproduce numpy's (pairwise sum, einsum), so its estimates are
    # bit for bit those of the former numpy implementation; numpy itself is the reference.
    rng = np.random.default_rng(count)
    for _ in range(200):
        a = rng.uniform(0.0, 1.0, count) * 10.0 ** rng.integers(-6, 6, count)
        b = rng.normal(size=count)
        assert landmarks_module._pairwise_sum(a) == a.sum()
        assert landmarks_module._dot(a, b) == np.einsum("gk,gk->g", a[None], b[None])[0]
