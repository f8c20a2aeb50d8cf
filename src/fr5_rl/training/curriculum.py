"""A reverse curriculum from the scripted expert's trajectories, for learning grasp from reward.

PPO from the plain start never lifts the cup: the first reward for a lift needs the tcp
lowered round the cup, the fingers closed at the right moment and the arm raised, all by
chance, and the cheaper thing learnt first is to rush in and topple it. Started part-way
along a successful trajectory (the scripted expert's, run for a random number of steps after
the reset), the policy meets the lift reward within its first episodes. The starts then move
back toward the plain reset as it succeeds, until every episode is the task itself.

The expert only sets the start state: no action of it is trained on, and what the policy
learns comes from the reward of the steps it takes itself (evaluation uses plain resets).
"""
from __future__ import annotations

import json
from collections import deque
from pathlib import Path
from typing import Any, Deque, Dict, Generator, List, Optional, Tuple

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from ..expert import ScriptedExpert
from .hyperparameters import ExpertStartSettings

STATE_FILE = "curriculum.json"
# The plain task as a reach-back level, in logs and plots: one curve that ends above 1.
PLAIN_LEVEL = 1.1


def first_prefix(reach_back: float, max_steps: int) -> int:
    """The shortest expert prefix drawn at ``reach_back`` (the start furthest back)."""
    return int(round((1.0 - reach_back) * max_steps))


def spare_seed(seed: int) -> int:
    """The seed of a spare environment whose live one was seeded ``seed``: a stream of its own."""
    return int(np.random.SeedSequence((int(seed), 0x5BA2E)).generate_state(1)[0])


def _run_to_end(generator: Generator[None, None, Any]) -> Any:
    """Run a generator through; its return value."""
    while True:
        try:
            next(generator)
        except StopIteration as finished:
            return finished.value


class ExpertStartWrapper(gym.Wrapper):
    """Each reset runs the scripted expert for ``k`` steps, ``k`` drawn uniformly from
    ``[(1 - reach_back) * max_steps, max_steps]``; the policy's episode starts there.

    ``reach_back`` 0 starts every episode where the expert is ``max_steps`` along; 1 draws
    from the whole way back to the reset; None is the plain task (no prefix).

    The frontier is where that range begins, below ``frontier_end``: the starts furthest back,
    new since the curriculum's last step back. A share ``frontier_share`` of the resets draws
    there, so the hardest starts are practised most. The info of an episode's last step says
    its ``expert_steps``, from which the curriculum tells frontier starts.

    An expert prefix that ends the episode (success, or a failure it ran into) is not a
    start: the environment is reset again and a shorter prefix drawn, below the step that
    ended it; after ``retries`` such prefixes, the episode starts plain. The prefix's steps
    count toward the task's step limit, as they would had the policy taken them.

    With a ``spare``, every automatic reset plays a start the spare prepared while the episode
    before it ran, and the two environments swap. Each start comes from its environment's own
    random stream (the spare's seeded from the live one's seed), so the starts differ from those
    drawn without a spare, but not with the time the preparation got: a level change finishes
    the preparation under way before dropping it.

    :param env: an ``FR5Env`` (or a wrapper of one).
    :param max_steps: the longest expert prefix (control periods): about where the expert
        has the object lifted and is holding it.
    :param reach_back: see above; set by the curriculum with :meth:`set_reach_back`.
    :param frontier_share: share of the resets drawn from the frontier, in [0, 1].
    :param episodes_per_replay: starts drawn at once and met along one replay (1: one replay per
        episode); see :meth:`_replay`.
    :param spare: a second environment built as ``env`` was, or None. With one, the next
        episode's start is prepared in the spare while the live environment plays (see
        :meth:`idle_work`), and each automatic reset swaps the two: the replay leaves the reset's
        critical path. Not with ``episodes_per_replay`` above 1.
    """

    retries = 3

    def __init__(self, env: gym.Env, max_steps: int, reach_back: Optional[float] = 1.0,
                 frontier_share: float = 0.0, episodes_per_replay: int = 1,
                 spare: Optional[gym.Env] = None) -> None:
        super().__init__(env)
        if episodes_per_replay < 1:
            raise ValueError(f"episodes_per_replay must be at least 1, got {episodes_per_replay}")
        if spare is not None and episodes_per_replay > 1:
            raise ValueError("a spare environment prepares one start at a time: use it with "
                             "episodes_per_replay 1, or drop the spare")
        # The spare and its expert, the generator preparing its next start (None: none begun),
        # and that start once ready: (observation, info).
        self._spare = spare
        self._spare_expert = None if spare is None else ScriptedExpert(spare)
        self._preparation: Optional[Generator[None, None, Tuple[np.ndarray, Dict[str, Any]]]] = None
        self._prepared: Optional[Tuple[np.ndarray, Dict[str, Any]]] = None
        self._preparation_error: Optional[BaseException] = None
        self.max_steps = int(max_steps)
        self.frontier_share = float(frontier_share)
        self.episodes_per_replay = int(episodes_per_replay)
        self.reach_back: Optional[float] = None
        self.frontier_end = self.max_steps + 1
        # Starts saved along the last replay, not yet played, the furthest last:
        # (prefix, saved episode, its observation, the reset's info).
        self._saved_starts: List[Tuple[int, Any, np.ndarray, Dict[str, Any]]] = []
        self.set_reach_back(reach_back)
        self.expert = ScriptedExpert(env)
        self.prefix = 0

    def set_reach_back(self, reach_back: Optional[float], frontier_end: Optional[int] = None) -> None:
        """:param reach_back: fraction of ``max_steps`` back from its end starts are drawn from
            (clipped to [0, 1]), or None for plain resets.
        :param frontier_end: the frontier's first prefix not in it: the previous level's first
            prefix (None: the whole range is new)."""
        # A start the spare is preparing was drawn under the level before. It is finished, not
        # cut short, so the spare's random stream is the same however far it had got, then dropped.
        preparing = self._has_preparation()
        if preparing:
            self._finish_preparation()
        self.reach_back = None if reach_back is None else min(max(float(reach_back), 0.0), 1.0)
        self.frontier_end = self.max_steps + 1 if frontier_end is None else int(frontier_end)
        self._discard_saved_starts()  # drawn under the level before
        if preparing:
            self._begin_preparation({})

    def prefix_range(self) -> Tuple[int, int]:
        """The expert steps drawn from, both ends included ((0, 0): plain resets)."""
        if self.reach_back is None:
            return 0, 0
        return first_prefix(self.reach_back, self.max_steps), self.max_steps

    def reset(self, **kwargs: Any) -> Tuple[np.ndarray, Dict[str, Any]]:
        if self._spare is not None:
            observation, info = self._reset_from_spare(kwargs)
        elif self._saved_starts and not kwargs:
            return self._play_saved_start()
        else:
            self._discard_saved_starts()
            observation, info = _run_to_end(self._start(self.env, self.expert, kwargs))
        self.prefix = info["expert_steps"]
        return observation, info

    def _start(self, env: gym.Env, expert: ScriptedExpert, kwargs: Dict[str, Any]
               ) -> Generator[None, None, Tuple[np.ndarray, Dict[str, Any]]]:
        """Reset ``env`` and run ``expert`` to a drawn start, yielding after each expert step;
        returns the start's observation and info (its ``expert_steps`` included). Everything
        drawn comes from ``env``'s own random stream, so the start is the same however its steps
        are spread in time."""
        observation, info = env.reset(**kwargs)
        random = env.unwrapped.np_random
        low, high = self.prefix_range()
        count = self.episodes_per_replay if self.reach_back is not None else 1
        # Each start's range, the frontier's share drawn once per start (retries keep it).
        highs = [max(min(self.frontier_end - 1, high), low)
                 if self.reach_back is not None and self.frontier_share > 0.0 and random.random() < self.frontier_share
                 else high for _ in range(count)]
        for _ in range(self.retries):
            observation, info, taken = yield from self._replay(env, expert, observation, info, sorted(
                int(random.integers(low, start_high + 1)) for start_high in highs))
            if taken is None:
                return observation, info
            observation, info = env.reset()
            # The step that ended the replay was step `taken`: shorter starts only.
            highs = [min(start_high, taken - 1) for start_high in highs]
            low = min(low, taken - 1)
        return observation, dict(info, expert_steps=0)

    def _replay(self, env: gym.Env, expert: ScriptedExpert, observation: np.ndarray, info: Dict[str, Any],
                prefixes: List[int]) -> Generator[None, None, Tuple[np.ndarray, Dict[str, Any], Optional[int]]]:
        """Run the expert from the reset through the starts ``prefixes`` (ascending), yielding
        after each step: the furthest is played now, the others are saved on the way
        (:meth:`FR5Env.save_state`) for the next resets. A replay the expert's episode ends before
        some starts keeps those it passed. Returns the start's observation and info and None, or,
        when the episode ended before the first start, the last observation, the reset's info
        and the steps taken."""
        unwrapped = env.unwrapped
        expert.reset()
        taken, ended, passed = 0, False, []
        for index, prefix in enumerate(prefixes):
            while taken < prefix and not ended:
                observation, _, terminated, truncated, _ = env.step(expert.act(observation))
                taken += 1
                ended = terminated or truncated
                yield
            if ended:
                break
            # The last start is played from the live episode; the others are saved on the way.
            saved = None if index == len(prefixes) - 1 else unwrapped.save_state()
            passed.append((prefix, saved, observation, info))
        if not passed:
            return observation, info, taken
        if ended:  # the furthest start passed is played from its saved state
            self._saved_starts = passed
            return (*self._play_saved_start(), None)
        prefix, _, observation, info = passed.pop()
        self._saved_starts = passed
        return observation, dict(info, expert_steps=prefix), None

    # -- the spare: the next start prepared while this episode plays ------------------------
    def _reset_from_spare(self, kwargs: Dict[str, Any]) -> Tuple[np.ndarray, Dict[str, Any]]:
        """An automatic reset plays the spare's prepared start (finishing it here if idle time
        did not) and sets the spare preparing the next. An explicit one (a seed or options)
        starts the live environment now and the spare afresh, seeded from that seed."""
        if kwargs or not self._has_preparation():
            self._finish_preparation()  # its draws all made: the spare's random stream stays the same
            observation, info = _run_to_end(self._start(self.env, self.expert, kwargs))
            seed = kwargs.get("seed")
            self._begin_preparation({} if seed is None else {"seed": spare_seed(seed)})
            return observation, info
        observation, info = self._finish_preparation()
        self.env, self._spare = self._spare, self.env
        self.expert, self._spare_expert = self._spare_expert, self.expert
        self._begin_preparation({})
        return observation, info

    def _has_preparation(self) -> bool:
        """Whether the spare has a start under way or ready."""
        return self._preparation is not None or self._prepared is not None

    def _begin_preparation(self, kwargs: Dict[str, Any]) -> None:
        self._prepared, self._preparation_error = None, None
        self._preparation = self._start(self._spare, self._spare_expert, kwargs)

    def idle_work(self) -> bool:
        """Take one step of preparing the spare's next start (one expert step, 0.37 ms for grasp):
        what a vectorised env's process calls while it would otherwise wait.

        :return: whether there was work to do (False: the next start is ready, or there is no
            spare).
        """
        if self._preparation is None:
            return False
        try:
            next(self._preparation)
        except StopIteration as finished:
            self._prepared, self._preparation = finished.value, None
        except Exception as error:  # raised by the reset that needs the start, not here in idle time
            self._preparation_error, self._preparation = error, None
        return True

    def _finish_preparation(self) -> Optional[Tuple[np.ndarray, Dict[str, Any]]]:
        """Run what is left of the spare's preparation; its start (None: nothing was begun)."""
        while self.idle_work():
            pass
        if self._preparation_error is not None:
            error, self._preparation_error = self._preparation_error, None
            raise error
        prepared, self._prepared = self._prepared, None
        return prepared

    def _play_saved_start(self) -> Tuple[np.ndarray, Dict[str, Any]]:
        env = self.env.unwrapped
        self.prefix, saved, observation, info = self._saved_starts.pop()
        env.restore_state(saved)
        env.discard_state(saved)
        return observation, dict(info, expert_steps=self.prefix)

    def _discard_saved_starts(self) -> None:
        env = self.env.unwrapped
        while self._saved_starts:
            env.discard_state(self._saved_starts.pop()[1])

    def set_wrapper_attr(self, name: str, value: Any, *, force: bool = True) -> bool:
        """Gymnasium's, except that an attribute of the environment inside is set on the spare
        too: the two swap at every automatic reset."""
        if self._spare is not None and not hasattr(self, name) and self.env.set_wrapper_attr(name, value, force=False):
            self._spare.set_wrapper_attr(name, value, force=False)
            return True
        return super().set_wrapper_attr(name, value, force=force)

    def close(self) -> None:
        self._discard_saved_starts()
        self._preparation, self._prepared = None, None
        if self._spare is not None:
            self._spare.close()
        super().close()

    def step(self, action: np.ndarray) -> Tuple[np.ndarray, float, bool, bool, Dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:  # what the curriculum reads; nothing added to the other steps
            info = dict(info, expert_steps=self.prefix)
        return observation, reward, terminated, truncated, info


class ExpertStartCurriculum(BaseCallback):
    """Moves the expert-prefixed starts back as training episodes succeed.

    Starts are first drawn from the last ``first_reach_back`` of the expert's prefix (the cup
    about to be lifted or held up). Over the last ``window`` finished training episodes that
    began at the frontier (each counted by its final ``info['is_success']``), a success rate
    of at least ``promote_at`` adds ``step_back`` to the reach-back in every environment, up
    to 1 (starts anywhere from the reset on), then once more to the plain task; the window
    starts over at each step. Judging the frontier alone matters: over all starts, the easy
    late ones carried the rate past ``promote_at`` while starts from the reset never succeeded,
    and the plain task was reached with 0 % success from it. The
    state and its history are written to ``run_dir/curriculum.json`` at each change, so a
    resumed run continues from it and the learning curve can draw it.

    :param settings: the ``expert_start`` section of the hyperparameter file.
    :param run_dir: the run directory (None: nothing written).
    """

    def __init__(self, settings: ExpertStartSettings, run_dir: Optional[Path] = None, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.settings = settings
        self.run_dir = run_dir
        self.reach_back: Optional[float] = settings.first_reach_back
        self.outcomes: Deque[bool] = deque(maxlen=settings.window)
        # Every change: {"reach_back", "num_timesteps"} (for the learning curve).
        self.history: List[Dict[str, Any]] = []
        self.frontier_end: Optional[int] = None  # set with each level (_apply)

    def _on_training_start(self) -> None:
        path = None if self.run_dir is None else self.run_dir / STATE_FILE
        if path is not None and path.is_file():
            saved = json.loads(path.read_text())
            self.reach_back, self.history = saved["reach_back"], saved.get("history", [])
        elif not self.history:
            self._record()
        self._apply()

    def _record(self) -> None:
        self.history.append({"reach_back": self.reach_back, "num_timesteps": int(self.num_timesteps)})
        if self.run_dir is not None:
            (self.run_dir / STATE_FILE).write_text(json.dumps(
                {"reach_back": self.reach_back, "num_timesteps": int(self.num_timesteps), "history": self.history}))

    def _apply(self) -> None:
        # The frontier: the starts this level adds to the one before (none before: all of them).
        previous = self.history[-2]["reach_back"] if len(self.history) >= 2 else None
        self.frontier_end = None if previous is None else first_prefix(previous, self.settings.max_steps)
        self.training_env.env_method("set_reach_back", self.reach_back, self.frontier_end)

    def _on_step(self) -> bool:
        s = self.settings
        if self.reach_back is None:
            return True
        # An episode begun before the last step back started at or after the frontier's end.
        for info, done in zip(self.locals["infos"], self.locals["dones"]):
            if done and (self.frontier_end is None or info.get("expert_steps", 0) < self.frontier_end):
                self.outcomes.append(bool(info.get("is_success", False)))
        if len(self.outcomes) == s.window and np.mean(self.outcomes) >= s.promote_at:
            self.reach_back = None if self.reach_back >= 1.0 else min(round(self.reach_back + s.step_back, 6), 1.0)
            self.outcomes.clear()
            self._record()
            self._apply()
            if self.verbose:
                print(f"curriculum: reach_back {self.reach_back} at {self.num_timesteps} steps")
        return True

    def _on_rollout_end(self) -> None:
        self.logger.record("curriculum/reach_back", PLAIN_LEVEL if self.reach_back is None else self.reach_back)
