"""Tracking the object through the frames in which the robot hides it or holds it (pure numpy;
the detector node feeds :class:`ObjectTracker` each frame's detector answer, the tcp pose and
the gripper opening).

The tracker's settings are the ``tracker`` section of ``config/detector.yaml``
(:class:`TrackerSettings`, no defaults in code). Its state is explicit: a :class:`Track` whose
:class:`TrackState` says whether the object is lost, seen, hidden on the table or in the hand.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from ..config import ConfigError
from ..objects import ObjectShape, distance_to_upright_object, held_in_tcp
from ..transforms import quaternion_from_matrix
from .camera_model import Intrinsics
from .detector import Detection, DetectorSettings, Refusal, RefusalReason, TableRegion, load_section

# Refusals about what the frame shows (the others are about the frame itself).
SCENE_REFUSALS = (RefusalReason.NO_OBJECT, RefusalReason.SEVERAL_OBJECTS, RefusalReason.OCCLUDED)


def rotation_z(yaw: float) -> np.ndarray:
    """The 3x3 rotation by ``yaw`` (rad) about z: an upright object's orientation at that yaw."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class TrackState(enum.Enum):
    """The tracker's state (:attr:`ObjectTracker.state`); in a :class:`TrackedObject`, where its
    position comes from (never LOST there)."""

    LOST = "lost"            # no object tracked: the next lone detection starts a track
    SEEN = "seen"            # detected in this very frame (the tracker: standing where last detected)
    HIDDEN = "hidden"        # the robot hides it: its last seen position, for a bounded time
    IN_HAND = "in hand"      # the fingers hold it: it moves with the tcp


@dataclass(frozen=True)
class TrackedObject:
    """The object pose and shape to publish for one frame.

    :param position_table: object centre (m) in the table frame.
    :param state: why this position is believed (:class:`TrackState`).
    :param last_seen: stamp (s) of the frame that last detected it (or in which the hand let it go).
    :param detection: this frame's detection (state SEEN), else None.
    :param position_tcp: in the hand: the centre (m) in the tcp frame (it moves with the tcp).
    :param yaw: rad, table frame: the object's own x axis (a box's longer top side; any of its
        symmetric yaws, modulo pi, pi / 2 for a square). SEEN: this frame's; HIDDEN: the last
        seen one (or the one the hand turned it to before letting go); IN_HAND: turned with the
        tcp since it was taken. Its orientation in the table frame is Rz(yaw) (upright).
    :param shape: the object's kind and extents along its own x, y, z (m; the last seen ones
        unless SEEN); None when never measured.
    :param orientation_tcp: in the hand: the object's orientation in the tcp frame, quaternion
        (x, y, z, w), fixed from the moment it was taken (it turns with the tcp).
    """

    position_table: Tuple[float, float, float]
    state: TrackState
    last_seen: float
    detection: Optional[Detection] = None
    position_tcp: Optional[Tuple[float, float, float]] = None
    yaw: float = 0.0
    shape: Optional[ObjectShape] = None
    orientation_tcp: Optional[Tuple[float, float, float, float]] = None


@dataclass(frozen=True)
class TrackerSettings:
    """How long and under which evidence a hidden object is still believed where it was: the
    ``tracker`` section of ``config/detector.yaml``, where every default lives (:meth:`from_yaml`).

    :param hidden_timeout: s after the last sighting during which a hidden object's last position
        is still published; 0 switches tracking off (every hidden frame holds).
    :param in_hand_timeout: s after the last sighting during which an object held between the
        fingers is published at the tcp (a slipping object cannot be told from a held one).
    :param max_table_fraction: where the last seen top face was, at most this fraction of the
        pixels may show the bare table; more means the object has gone (hold).
    :param front_tolerance: m; a depth this much nearer than the top face is something in front of it.
    :param grasp_radius: m; the fingers hold the object only if the tcp was this close to it (its
        axis, from the table to its top: :func:`~fr5_rl.objects.distance_to_upright_object`) when
        they came around it (:meth:`ObjectTracker._grasp_pose`).
    :param grasp_width_margin: m; the fingers are closed on it when their opening is at most the
        object's measured width plus this (and more than ``min_grasp_fraction`` of it).
    :param min_grasp_fraction: fingers closed narrower than this fraction of the object's
        measured width have nothing between them (a held object yields a little, not by half).
    :param closing_tolerance: m; fingers that closed by more than this since the last frame are
        still closing: the object is taken into the hand only once they stop on it (earlier, the
        tcp may still move relative to it).
    :param lift_evidence: m; the tcp risen this far (table z) above where the fingers came around
        the object, with them still at a width that holds it: it is in the hand even while they
        go on closing (a fast gripper squeezes on for frames while the arm already lifts; waiting
        for the fingers to stop left it "hidden" on the table and the policy let go).
    :param closing_axis: the direction (tcp frame) the fingers close along. Closing fingers push
        the object to their middle, so in the hand its offset along this axis is 0.
    :param gate_height: m; while an object is tracked, a detection whose top differs from its
        standing top height by more than this is a part of it (a finger hides the rest): hidden.
    :param gate_size: likewise for a top face width that differs by more than this fraction.
    :param nudge_radius: m; fingers closing or pressing beside a hidden object push it a little.
        Where its top face was shows bare table, the tracker looks for that face up to this far
        away (still hidden by something in front of it) before it drops the track; 0: never.
    :param nudge_step: m between the positions it looks at.
    :param square_width_tolerance: m; fingers stopped within this of one of a box's measured sides
        have squared it between the pads (the box turns until a face lies flat on each): in the
        hand its yaw is then the pads', of the four the nearest to the yaw last seen. A box nudged
        while the hand hid it was otherwise carried at the yaw it had before (17 degrees off in
        the rehearsal). Wider (across its corners, or on something else): the last seen yaw is
        kept. 0: always kept.
    :param release_opening: m; fingers opened this much wider than the narrowest they held the
        object at have let go of it. Measured against the object's top-face width alone, fingers
        71 mm open on a 69 mm cylinder (measured 61 mm wide, plus grasp_width_margin) still held
        it: the tracker lifted it with the hand that had just set it down, and the policy, seeing
        it still in the hand, never finished letting go. Applies when the fingers' command is
        unknown; with it (:meth:`ObjectTracker.update`'s ``commanded_width``) only fingers told to
        open wider than they hold, and opened by more than ``closing_tolerance``, let go: an
        object caught near a pad's edge widens the grip by 5-6 mm as it turns square between the
        pads, with the fingers still told to close (the rehearsal's place timeouts, stop 61).
    """

    hidden_timeout: float
    in_hand_timeout: float
    max_table_fraction: float
    front_tolerance: float
    grasp_radius: float
    grasp_width_margin: float
    min_grasp_fraction: float
    closing_tolerance: float
    lift_evidence: float
    closing_axis: List[float]
    gate_height: float
    gate_size: float
    nudge_radius: float
    nudge_step: float
    square_width_tolerance: float
    release_opening: float

    def check(self, source: str) -> None:
        """Refuse values the tracker cannot work with (called by :func:`fr5_rl.config.typed`)."""
        if min(self.hidden_timeout, self.in_hand_timeout, self.front_tolerance, self.grasp_radius,
               self.grasp_width_margin, self.min_grasp_fraction, self.nudge_radius, self.lift_evidence,
               self.square_width_tolerance, self.release_opening) < 0 \
                or self.nudge_step <= 0 or not 0 <= self.max_table_fraction <= 1:
            raise ConfigError(f"{source}: the tracking parameters must be >= 0 and max_table_fraction in [0, 1] "
                              "(hidden_timeout 0 switches tracking off), nudge_step > 0")
        if len(self.closing_axis) != 3 or not np.linalg.norm(self.closing_axis) > 0:
            raise ConfigError(f"{source}: closing_axis must be a non-zero 3-vector (the fingers' direction in "
                              f"the tcp frame), got {self.closing_axis}")

    @classmethod
    def from_yaml(cls, path_or_name: Union[str, Path] = "detector") -> "TrackerSettings":
        """The ``tracker`` section of ``config/detector.yaml`` (or of another file: a path, or a
        name in ``config/``), checked."""
        return load_section(cls, "tracker", path_or_name)


@dataclass
class Track:
    """What the tracker believes about the object. ``state`` says which fields mean something:
    none when LOST; the rest but ``in_tcp`` and ``rotation_tcp`` when SEEN or HIDDEN (it stands on the table at
    ``position``); all of them when IN_HAND.

    :param state: see :class:`TrackState`.
    :param position: the object's centre (m) in the table frame.
    :param top_height: its top face's height (m) above the table.
    :param size: its top face's width (m) when last seen.
    :param last_seen: stamp (s) of the frame that last detected it (or in which the hand let it go).
    :param in_front: fraction of its top face with something in front of it, at the last look.
    :param rest: its centre's height (m, table frame) and its top height (m) when last seen
        standing on the table: where the hand puts it down, and the table holds it up.
    :param in_tcp: its centre (m) in the tcp frame, while in the hand.
    :param yaw: rad, table frame: its own x axis (see :attr:`TrackedObject.yaw`).
    :param shape: its kind and extents when last seen; None: never measured.
    :param rotation_tcp: its orientation (3x3) in the tcp frame, while in the hand.
    :param held_width: the opening (m) the fingers hold it at, while in the hand: the narrowest
        seen, or with the fingers' command known, the newest while they are told to close; None:
        none known yet.
    """

    state: TrackState
    position: np.ndarray
    top_height: float
    size: float
    last_seen: float
    in_front: float
    rest: Tuple[float, float]
    in_tcp: np.ndarray
    yaw: float = 0.0
    shape: Optional[ObjectShape] = None
    rotation_tcp: np.ndarray = field(default_factory=lambda: np.eye(3))
    held_width: Optional[float] = None

    @classmethod
    def lost(cls) -> "Track":
        """No object tracked."""
        return cls(TrackState.LOST, np.zeros(3), 0.0, 0.0, 0.0, 0.0, (0.0, 0.0), np.zeros(3))


def footprint_view(depth: np.ndarray, intrinsics: Intrinsics, table_from_optical: np.ndarray,
                   table_height: float, min_height: float, centre_table: Sequence[float], top_height: float,
                   size: float, front_tolerance: float) -> Tuple[float, float, int]:
    """What the camera sees where an object's top face was: the fractions of its pixels with
    something in front of that face, and with the bare table (the object has gone).

    :param depth: (H, W) float metres along the optical axis, 0 = no data.
    :param table_from_optical: 4x4 pose (m) of the optical frame in the table frame.
    :param table_height: z (m) of the table top in the table frame (:class:`TableRegion`).
    :param min_height: m above the table below which a point is the table
        (:class:`DetectorSettings`).
    :param centre_table: the object's centre (m, table frame); only x, y are used.
    :param top_height: its top face's height (m) above the table.
    :param size: its top face's width (m).
    :param front_tolerance: m; nearer than the face by more than this is in front of it.
    :return: ``(in_front, table, samples)``: fractions of the face's sample points that lie in
        the image with depth, and how many those were (0: the face is out of view).
    """
    in_front, table, samples = footprint_views(depth, intrinsics, table_from_optical, table_height, min_height,
                                               np.asarray(centre_table, dtype=np.float64)[None, :2], top_height,
                                               size, front_tolerance)
    return float(in_front[0]), float(table[0]), int(samples[0])


def footprint_views(depth: np.ndarray, intrinsics: Intrinsics, table_from_optical: np.ndarray,
                    table_height: float, min_height: float, centres_xy: np.ndarray, top_height: float, size: float,
                    front_tolerance: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`footprint_view` for N candidate centres (N, 2) at once: arrays of N ``in_front``,
    ``table`` and ``samples``."""
    # Rings over the face, not its rim only: a finger in front of the rim still leaves the centre.
    radii = np.array([0.0, 0.3, 0.6, 0.85]) * (0.5 * size)
    angles = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    r, a = np.meshgrid(radii, angles)
    offsets = np.stack([(r * np.cos(a)).ravel(), (r * np.sin(a)).ravel()], axis=1)
    centres_xy = np.asarray(centres_xy, dtype=np.float64).reshape(-1, 2)
    n, m = len(centres_xy), len(offsets)
    xy = (centres_xy[:, None, :] + offsets[None, :, :]).reshape(-1, 2)
    points = np.stack([xy[:, 0], xy[:, 1], np.full(n * m, table_height + top_height), np.ones(n * m)])
    table_from_optical = np.asarray(table_from_optical, dtype=np.float64)
    optical = np.linalg.inv(table_from_optical) @ points
    expected = optical[2]
    used = expected > 1e-6  # in front of the camera, then: in the image, then: with depth
    u = np.full(n * m, -1)
    v = np.full(n * m, -1)
    pixels = intrinsics.project(optical[:3, used].T)
    u[used], v[used] = np.rint(pixels[:, 0]).astype(int), np.rint(pixels[:, 1]).astype(int)
    used &= (u >= 0) & (u < intrinsics.width) & (v >= 0) & (v < intrinsics.height)
    measured = np.zeros(n * m)
    measured[used] = depth[v[used], u[used]]
    used &= measured > 0.0
    rx, ry = intrinsics.ray(u, v)
    seen_height = (table_from_optical[2] @ np.stack([rx * measured, ry * measured, measured, np.ones(n * m)])
                   - table_height)
    in_front = used & (measured < expected - front_tolerance)
    table = used & (seen_height < min_height) & ~in_front
    samples = used.reshape(n, m).sum(axis=1)
    share = lambda mask: np.where(samples > 0, mask.reshape(n, m).sum(axis=1) / np.maximum(samples, 1), 0.0)  # noqa: E731
    return share(in_front), share(table), samples


class ObjectTracker:
    """Bridges the frames in which the robot hides the object it is about to grasp or holds.

    The detector refuses a hidden object (its visible part would give a biased centre), and
    it must: but the gripper hides the object exactly when the grasp policy needs it, going
    down around it, closing and lifting. A robot knows two more things than the camera: the
    object does not move on its own while the arm covers it, and once the fingers are closed
    on it, it moves with them. So, per frame:

    - detected: that position (SEEN);
    - the fingers have closed on it (their opening at most its measured width plus
      ``grasp_width_margin``, more than ``min_grasp_fraction`` of it, and no longer closing) with the
      tcp within ``grasp_radius`` of it, in this frame or in an earlier one since which they have
      kept that width (a policy lifts at once: by the frame that shows the fingers stopped, the
      spot where it stood may be bare), checked before the look at that spot: it is in the hand
      (IN_HAND). Fingers still closing count too once the tcp has risen ``lift_evidence`` above
      where they came around it (a fast gripper squeezes on while the arm lifts). Its offset in the tcp
      frame is kept and published *in the tcp frame*, so whoever uses it places it with the
      newest tcp pose: no camera latency on a held object. It stays in the hand until the
      fingers open or close on nothing, where it would be the camera sees the bare table, or
      ``in_hand_timeout``;
    - not detected because something hides it (the refusal is OCCLUDED or NO_OBJECT, and where
      its top face was, the camera sees something in front of it rather than the bare table):
      its last position, for ``hidden_timeout`` after the last sighting (HIDDEN);
    - several candidates: those not the whole object (a top lower, higher, narrower or wider
      than its own: finger tips, a part of it) are set aside, and the rest is judged as above;
    - otherwise: hold. Several whole candidates, a bare table where it stood, or a timeout drop
      the track (LOST); a frame that holds for another reason leaves the track as it was.

    Each answer carries the object's yaw and shape too (:class:`TrackedObject`): a frame's
    detection gives them; hidden, the last seen ones stand; in the hand, its orientation in the
    tcp frame is kept from the moment it was taken, so it turns with the tcp (a policy placing a
    box at a goal yaw turns it with the wrist), and the yaw it was turned to stays when the hand
    lets go.

    Nothing here knows the object's colour. Pure numpy; the node feeds it each frame's
    result, the tcp pose and the gripper opening.

    The tracker's state is explicit (:class:`Track`: LOST, SEEN, HIDDEN or IN_HAND, and what it
    believes of the object); :attr:`state` tells it.

    :param settings: the ``tracker`` section of ``config/detector.yaml`` (:class:`TrackerSettings`).
    :param detector_settings: the detector's (its ``min_height``: what is bare table).
    :param table: the table plane the detector measures from.
    """

    def __init__(self, settings: TrackerSettings, detector_settings: DetectorSettings, table: TableRegion) -> None:
        self.settings = settings
        self.detector_settings = detector_settings
        self.table = table
        self._last_width: Optional[float] = None  # the fingers' opening (m) in the last frame that had one
        self._grasp_tcp: Optional[np.ndarray] = None  # see _grasp_pose
        self._grasp_low: Optional[np.ndarray] = None  # the lowest tcp pose (table z) with the fingers around it
        self._grasp_low_stamp = 0.0  # when it was taken (s)
        self._track = Track.lost()

    @property
    def state(self) -> TrackState:
        """LOST, or where the tracked object is believed to be (see :class:`TrackState`)."""
        return self._track.state

    def reset(self) -> None:
        """Forget the object (a new one will be detected before anything is published)."""
        self._track = Track.lost()
        self._grasp_tcp = None
        self._grasp_low = None

    def update(self, result: Union[Detection, Refusal], stamp: float, depth: Optional[np.ndarray] = None,
               intrinsics: Optional[Intrinsics] = None, table_from_optical: Optional[np.ndarray] = None,
               table_from_tcp: Optional[np.ndarray] = None, gripper_width: Optional[float] = None,
               commanded_width: Optional[float] = None) -> Union[TrackedObject, Refusal]:
        """The position to publish for one frame, or why to hold.

        :param result: the detector's answer for the frame.
        :param stamp: the frame's capture time (s).
        :param depth: the frame's depth (m), for the look at where a hidden object was.
        :param intrinsics: its camera model.
        :param table_from_optical: 4x4 pose (m) of the optical frame in the table frame.
        :param table_from_tcp: 4x4 pose (m) of the tcp in the table frame at ``stamp``; None
            when unknown (no in-hand tracking).
        :param gripper_width: the fingers' opening (m) at ``stamp``; None when unknown.
        :param commanded_width: the opening (m) the fingers were last told to go to, by ``stamp``;
            None when unknown (then a grip that widens by ``release_opening`` counts as let go).
        """
        if isinstance(result, Refusal) and result.reason not in SCENE_REFUSALS:
            return result  # a frame that could not be looked at says nothing about the object
        tcp = None if table_from_tcp is None else np.asarray(table_from_tcp, dtype=np.float64)
        closing = (gripper_width is not None and self._last_width is not None
                   and self._last_width - gripper_width > self.settings.closing_tolerance)
        letting_go = self._letting_go(gripper_width, commanded_width)
        if gripper_width is not None:
            self._last_width = gripper_width
        look = (depth, intrinsics, table_from_optical) if depth is not None and intrinsics is not None \
            and table_from_optical is not None else None
        if self._track.state is TrackState.IN_HAND:
            return self._follow_hand(result, stamp, look, tcp, gripper_width, commanded_width)
        tracking = self._track.state is not TrackState.LOST
        if tracking and isinstance(result, Refusal) and result.candidates:
            result = self._sort_out(result)
        if isinstance(result, Detection) and tracking:
            partial = self._partial(result)
            if partial is not None:
                result = Refusal(RefusalReason.OCCLUDED, partial)
        if isinstance(result, Detection):
            track = self._track
            track.state = TrackState.SEEN
            track.position = np.array(result.position_table, dtype=np.float64)
            track.top_height, track.size, track.last_seen = result.top_height, result.size, stamp
            track.rest = (float(track.position[2]), result.top_height)  # seen: standing on the table
            track.yaw, track.shape = result.yaw, result.shape
            if self._grasp_low is None or stamp >= self._grasp_low_stamp:
                # Standing, so not (yet) between the fingers; a frame captured before they came
                # around it (the camera's latency) says nothing about that.
                self._grasp_tcp = None
                self._grasp_low = None
            return TrackedObject(tuple(track.position.tolist()), TrackState.SEEN, stamp, result, yaw=track.yaw,
                                 shape=track.shape)
        if not tracking:
            return result
        if result.reason is RefusalReason.SEVERAL_OBJECTS:
            self.reset()
            return result
        s = self.settings
        age = stamp - self._track.last_seen
        if age > s.hidden_timeout:
            self.reset()
            return Refusal(result.reason, f"{result.detail}; hidden for {age:.1f} s > hidden_timeout "
                                          f"{s.hidden_timeout:g} s")
        if look is None:
            return result  # no look at where it stands: the track stays as it is
        # Closed on it before the look at where it stood: a fast lift carries it off that spot
        # within a frame, and the bare table there then means "in the hand", not "gone".
        grasped_from = self._grasp_pose(tcp, gripper_width, stamp, letting_go, commanded_width)
        lifted = (tcp is not None and grasped_from is not None and self._grasp_low is not None
                  and tcp[2, 3] - self._grasp_low[2, 3] >= s.lift_evidence)
        if lifted:
            grasped_from = self._grasp_low  # it rose with the fingers from there
        # Stopped on it (a frame without the opening cannot say so), or lifted with it.
        stopped = gripper_width is not None and not closing
        if (stopped or lifted) and tcp is not None and grasped_from is not None:
            self._take_into_hand(tcp, grasped_from, gripper_width)
            return self._held(TrackState.IN_HAND)
        gone = self._gone(look)
        if gone is not None and not self._nudged(look):
            self.reset()
            return Refusal(result.reason, f"{result.detail}; {gone}")
        if result.reason is RefusalReason.NO_OBJECT and self._track.in_front == 0.0:
            return result  # nothing in front of it and no object: not hidden, it was just not found
        return self._held(TrackState.HIDDEN)

    def hand_between_frames(self, stamp: float, table_from_tcp: Optional[np.ndarray],
                            gripper_width: Optional[float],
                            commanded_width: Optional[float] = None) -> Optional[TrackedObject]:
        """Between camera frames, from the tcp and the fingers alone: whether a tracked object
        (SEEN or HIDDEN) has just been lifted in the hand (the fingers around it, at a width that
        holds it, and the tcp ``lift_evidence`` above the lowest point where they were). A frame
        would say so a camera latency later (60-150 ms), by when a policy that sees the object left
        on the table has opened the hand; the environment's model of the tracker says so at once.

        :param stamp: now (s, the frames' clock).
        :param table_from_tcp: the tcp pose now (4x4, table frame); None: unknown (nothing changes).
        :param gripper_width: the fingers' opening now (m); None: unknown.
        :param commanded_width: the opening (m) the fingers were last told to go to; None: unknown.
        :return: the object, now IN_HAND, or None when nothing changed.
        """
        if self._track.state not in (TrackState.SEEN, TrackState.HIDDEN) or table_from_tcp is None \
                or gripper_width is None:
            return None
        tcp = np.asarray(table_from_tcp, dtype=np.float64)
        if self._grasp_pose(tcp, gripper_width, stamp, self._letting_go(gripper_width, commanded_width, False),
                            commanded_width) is None \
                or self._grasp_low is None \
                or tcp[2, 3] - self._grasp_low[2, 3] < self.settings.lift_evidence:
            return None
        self._take_into_hand(tcp, self._grasp_low, gripper_width)
        return self._held(TrackState.IN_HAND)

    def _follow_hand(self, result: Union[Detection, Refusal], stamp: float, look, tcp: Optional[np.ndarray],
                     width: Optional[float], commanded: Optional[float]) -> Union[TrackedObject, Refusal]:
        """:meth:`update` while the object is in the hand."""
        s, track = self.settings, self._track
        if tcp is not None:
            self._place((tcp @ np.append(track.in_tcp, 1.0))[:3], tcp)
        if isinstance(result, Detection) and self._far(result.position_table):
            self.reset()
            return Refusal(RefusalReason.SEVERAL_OBJECTS, "an object in the hand and one elsewhere")
        held = track.held_width
        if held is None or width is None:
            opened = False
        elif commanded is None:
            opened = width > held + s.release_opening
        else:
            # Told to close, a grip may still widen: an object caught off-centre, on a pad's edge,
            # turns square between the pads (58 -> 64 mm on a 65 mm cylinder, the fingers told 0).
            opened = commanded > held + s.closing_tolerance and width > held + s.closing_tolerance
        let_go = width is not None and (opened or not self._fits(width))
        if width is not None and not let_go:
            squeezing = commanded is not None and commanded < width
            track.held_width = width if held is None or squeezing else min(held, width)
        if let_go:
            # Let go (or closed on nothing): it stands on the table below where the hand left
            # it, as sure as a sighting; if it fell elsewhere, the look at its top face tells.
            # An unknown opening is not a let-go: a gripper read back at 10 Hz leaves frames
            # with none within 0.1 s, and the object, taken for standing on the table, was
            # dropped 2 s later while still in the hand (the rehearsal's grasp timeouts). Nor is
            # an unknown tcp: the object stays where the hand last had it.
            track.last_seen = stamp
            track.position[2], track.top_height = track.rest
            return self._held(TrackState.HIDDEN)
        if stamp - track.last_seen > s.in_hand_timeout:
            self.reset()
            return Refusal(RefusalReason.OCCLUDED, f"in the hand, unseen for more than in_hand_timeout "
                                                   f"{s.in_hand_timeout:g} s")
        gone = self._gone(look) if look is not None else None
        if gone is not None:
            self.reset()
            return Refusal(RefusalReason.NO_OBJECT, f"not in the hand any more: {gone}")
        return self._held(TrackState.IN_HAND)

    def _letting_go(self, width: Optional[float], commanded: Optional[float], by_trend: bool = True) -> bool:
        """Whether the fingers, ``width`` (m) open, are opening: told to open wider than they are
        (``commanded``, m), or, with the command unknown and ``by_trend``, wider than at the last
        frame. Fingers opening off an object they have let go pass through widths that hold it, and
        the hand rising from it then looked like a lift: the tracker took a set-down object back
        into the hand and carried it up with the hand (the rehearsal, stop 63)."""
        if width is None:
            return False
        tolerance = self.settings.closing_tolerance
        if commanded is not None:
            return commanded > width + tolerance
        return by_trend and self._last_width is not None and width - self._last_width > tolerance

    def _grasp_pose(self, tcp: Optional[np.ndarray], width: Optional[float], stamp: float,
                    letting_go: bool = False, commanded: Optional[float] = None) -> Optional[np.ndarray]:
        """The tcp pose (4x4, table frame) at which the fingers came around the tracked object,
        while they stay at a width that holds it; None otherwise.

        The fingers stop closing a frame or two after they reach the object, and a policy may lift
        at once: by the frame that shows them stopped, the tcp can be further than
        ``grasp_radius`` from where the object stood. The pose of the last frame that had the
        fingers around it is kept until they open past, or close below, its width, the object is
        seen standing, or the track is reset; a frame without the tcp pose or the opening
        keeps it. Fingers ``letting_go`` (:meth:`_letting_go`) are not around it: that forgets it;
        fingers told to open wider than the object (``commanded``, m) do not hold it."""
        if letting_go:
            self._grasp_tcp = None
            self._grasp_low = None
        elif self._closed_on_it(tcp, width, commanded):
            self._grasp_tcp = np.array(tcp, dtype=np.float64)
            if self._grasp_low is None or tcp[2, 3] < self._grasp_low[2, 3]:
                self._grasp_low, self._grasp_low_stamp = self._grasp_tcp, stamp
        elif width is not None and not self._fits(width):
            self._grasp_tcp = None
            self._grasp_low = None
        return self._grasp_tcp

    def _take_into_hand(self, tcp: np.ndarray, grasped_from: np.ndarray, width: Optional[float]) -> None:
        """Keep the object's offset in the tcp frame, centred between the fingers, as it was when
        the tcp stood at ``grasped_from``; place it with the tcp at ``tcp`` now. A box the fingers,
        ``width`` (m) open, squared between the pads takes their yaw (:meth:`_yaw_between_pads`)."""
        track = self._track
        squared = self._yaw_between_pads(grasped_from, width)
        if squared is not None:
            track.yaw = squared
        track.held_width = width
        self._grasp_tcp = None
        self._grasp_low = None
        track.in_tcp = held_in_tcp(grasped_from[:3, 3], grasped_from[:3, :3], track.position,
                                   self.settings.closing_axis)  # centred between the fingers
        # Upright at its yaw then; from now on it turns with the hand.
        track.rotation_tcp = grasped_from[:3, :3].T @ rotation_z(track.yaw)
        self._place((tcp @ np.append(track.in_tcp, 1.0))[:3], tcp)

    def _yaw_between_pads(self, grasped_from: np.ndarray, width: Optional[float]) -> Optional[float]:
        """The yaw (rad, table frame) of a box the fingers, ``width`` (m) open at the tcp pose
        ``grasped_from``, have squared between their pads: a face on each, so one of its axes lies
        along the closing axis; of the four such yaws, the nearest to the one last seen (a box
        squared turns by less than 45 degrees; which side is between the pads the width may not
        tell, the sides measured a few millimetres off). None: not a box, the width unknown or
        none of its sides (``square_width_tolerance``: across its corners, or on something
        else), or the fingers closing at a slant."""
        track, tolerance = self._track, self.settings.square_width_tolerance
        shape = track.shape
        if tolerance <= 0.0 or shape is None or shape.kind != "box" or width is None \
                or min(abs(width - shape.size[0]), abs(width - shape.size[1])) > tolerance:
            return None
        axis = grasped_from[:3, :3] @ np.asarray(self.settings.closing_axis, dtype=np.float64)
        axis /= np.linalg.norm(axis)
        if np.hypot(axis[0], axis[1]) < 0.9:  # the pads tilted: the box's faces need not lie on them
            return None
        quarter = np.pi / 2.0
        closing_yaw = float(np.arctan2(axis[1], axis[0]))
        return math.remainder(closing_yaw + quarter * round((track.yaw - closing_yaw) / quarter), 2.0 * np.pi)

    def _place(self, position: np.ndarray, tcp: np.ndarray) -> None:
        """Move the held object to ``position`` (m, table frame), given the tcp pose ``tcp``
        (4x4, table frame), and turn it with the tcp."""
        # The table holds it up: a tcp pressing lower slides the fingers along it.
        track = self._track
        x_axis = tcp[:3, :3] @ track.rotation_tcp[:, 0]
        if np.hypot(x_axis[0], x_axis[1]) > 1e-6:  # its x straight up or down: no yaw to tell, keep the last
            track.yaw = float(np.arctan2(x_axis[1], x_axis[0]))
        position = np.array(position, dtype=np.float64)
        if position[2] < track.rest[0]:
            position[2] = track.rest[0]
            track.in_tcp = (np.linalg.inv(tcp) @ np.append(position, 1.0))[:3]
        track.top_height = track.rest[1] + float(position[2] - track.rest[0])
        track.position = position

    def _sort_out(self, several: Refusal) -> Union[Detection, Refusal]:
        """Several candidates while an object is tracked: finger tips lower than
        ``max_object_height`` beside it, or pieces of it between the fingers, stand on the table
        like objects. Those that are not the whole object (:meth:`_partial`) are not another
        one: the one whole candidate is the object; none, and it is hidden among them; more
        than one, and which is which cannot be told."""
        whole = [c for c in several.candidates if self._partial(c) is None]
        if len(whole) == 1:
            return whole[0]
        if not whole:
            return Refusal(RefusalReason.OCCLUDED, f"{len(several.candidates)} pieces, none of them the whole "
                                                   f"object: parts of it and of the fingers")
        return several

    def _partial(self, detection: Detection) -> Optional[str]:
        """Why a detection cannot be the whole tracked object (its top lower or higher, or its
        face narrower or wider, than the object's when it was last seen standing: a part of it
        beside a finger, or a finger tip), or None."""
        s = self.settings
        rest_top = self._track.rest[1]
        if abs(detection.top_height - rest_top) > s.gate_height:
            return (f"a piece {detection.top_height * 100:.1f} cm high where the object stands "
                    f"{rest_top * 100:.1f} cm: part of it (gate_height {s.gate_height:g} m)")
        size = self._track.size
        if size > 0.0 and abs(detection.size / size - 1.0) > s.gate_size:
            return (f"a piece {detection.size * 100:.1f} cm wide where the object is {size * 100:.1f} cm: "
                    f"part of it (gate_size {s.gate_size:g})")
        return None

    def _gone(self, look) -> Optional[str]:
        """Why the camera says the object is not where it is believed to be, or None."""
        depth, intrinsics, table_from_optical = look
        track = self._track
        track.in_front, table, samples = footprint_view(
            depth, intrinsics, table_from_optical, self.table.table_height, self.detector_settings.min_height,
            track.position, track.top_height, track.size, self.settings.front_tolerance)
        if samples == 0:
            return "where it should be is out of view"
        if table > self.settings.max_table_fraction:
            return f"where it should be the table is bare ({table:.0%} of its top face)"
        return None

    def _nudged(self, look) -> bool:
        """Where the hidden object's top face would be after a push of up to ``nudge_radius``:
        the place with the least bare table among those where something stands in front of the
        face (the hand that pushed it) and at most ``max_table_fraction`` of it shows the table,
        the nearest on a tie. Moves the track there; False (the track unchanged) when none is."""
        s, track = self.settings, self._track
        if s.nudge_radius <= 0.0 or s.nudge_step <= 0.0:
            return False
        depth, intrinsics, table_from_optical = look
        steps = np.arange(-int(s.nudge_radius // s.nudge_step), int(s.nudge_radius // s.nudge_step) + 1)
        shifts = np.stack(np.meshgrid(steps, steps), axis=-1).reshape(-1, 2) * s.nudge_step
        distance = np.hypot(shifts[:, 0], shifts[:, 1])
        around = (distance > 0.0) & (distance <= s.nudge_radius + 1e-9)
        shifts, distance = shifts[around], distance[around]
        in_front, table, samples = footprint_views(depth, intrinsics, table_from_optical, self.table.table_height,
                                                   self.detector_settings.min_height, track.position[:2] + shifts,
                                                   track.top_height, track.size, s.front_tolerance)
        fits = np.flatnonzero((samples > 0) & (in_front > 0.0) & (table <= s.max_table_fraction))
        if fits.size == 0:
            return False
        best = fits[np.lexsort((distance[fits], table[fits]))[0]]
        track.position = track.position.copy()
        track.position[:2] += shifts[best]
        track.in_front = float(in_front[best])
        return True

    def _held(self, state: TrackState) -> TrackedObject:
        """The track, now in ``state`` (HIDDEN or IN_HAND), as the position to publish."""
        track = self._track
        track.state = state
        in_hand = state is TrackState.IN_HAND
        in_tcp = tuple(track.in_tcp.tolist()) if in_hand else None
        orientation = quaternion_from_matrix(track.rotation_tcp) if in_hand else None
        return TrackedObject(tuple(track.position.tolist()), state, track.last_seen, None, in_tcp, track.yaw,
                             track.shape, orientation)

    def _closed_on_it(self, tcp: Optional[np.ndarray], width: Optional[float],
                      commanded: Optional[float] = None) -> bool:
        """Whether the fingers, ``width`` (m) open at the tcp pose ``tcp`` and last told to go to
        ``commanded`` (m; None: unknown), hold the tracked object."""
        s = self.settings
        if tcp is None or width is None or self._track.state is TrackState.LOST:
            return False
        # Told to stay open wider than the object, they are not on it, whatever their width: open
        # (80 mm) over a 70 mm cylinder they "fitted" within grasp_width_margin and, not closing,
        # counted as stopped on it; the first hidden frame took it into the hand, and the object
        # then moved with the tcp as it lined up: 15 mm off where it stood when the fingers did
        # close (the rehearsal, stop 64).
        if commanded is not None and commanded >= self._track.size:
            return False
        track = self._track
        # Near the object, not its centre: a tall one is grasped near its top, 4-5 cm above its
        # centre, and was never taken into the hand (dropped as hidden 2 s later, the rehearsal's
        # timeouts with the 10 cm cylinders).
        half_height = self.table.table_height + track.top_height - float(track.position[2])
        near = distance_to_upright_object(tcp[:3, 3], track.position, max(half_height, 0.0)) <= s.grasp_radius
        return near and self._fits(width)

    def _fits(self, width: float) -> bool:
        # The fingers' opening (m) with the object between them.
        s = self.settings
        size = self._track.size
        return s.min_grasp_fraction * size < width <= size + s.grasp_width_margin

    def _far(self, position_table: Sequence[float]) -> bool:
        # A detection this far from the held object's centre is another object.
        return float(np.linalg.norm(np.subtract(position_table, self._track.position)[:2])) > self.settings.grasp_radius
