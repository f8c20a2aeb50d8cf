"""Vectorised environments for training: several environments per subprocess.

SB3's ``SubprocVecEnv`` gives every environment its own process. On a small machine that is
the slow way: a reach step costs about 0.4 ms of physics and Python, while sending it to a
process and back costs about as much again, and four processes on two cores spend their time
being scheduled. :class:`ChunkedSubprocVecEnv` cuts the environments into one chunk per core:
the first chunk steps in the trainer's own process while the others step, each as a
``DummyVecEnv``, in worker processes, so one message carries a whole chunk of actions and the
trainer's core does not sit idle waiting for them.

The semantics are ``DummyVecEnv``'s (automatic reset, ``terminal_observation``,
``reset_infos``, per-environment seeds and options), because each worker *is* one; how the
environments are spread over processes changes speed only, never results.
"""
from __future__ import annotations

import multiprocessing as mp
from typing import Any, Callable, List, Optional, Sequence, Tuple

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv
from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper, VecEnv, VecEnvIndices


def split_evenly(n_items: int, n_chunks: int) -> List[range]:
    """``range(n_items)`` cut into ``n_chunks`` consecutive ranges whose sizes differ by at most one.

    :raises ValueError: ``n_chunks`` is not between 1 and ``n_items``.
    """
    if not 1 <= n_chunks <= n_items:
        raise ValueError(f"cannot spread {n_items} environments over {n_chunks} processes; "
                         f"use 1..{n_items} processes")
    bounds = [round(i * n_items / n_chunks) for i in range(n_chunks + 1)]
    return [range(bounds[i], bounds[i + 1]) for i in range(n_chunks)]


def split_with_lighter_first(n_items: int, n_chunks: int, first_fewer: int) -> List[range]:
    """:func:`split_evenly`, with the first chunk ``first_fewer`` items lighter (at least one
    item left in it; a single chunk holds everything) and the rest spread evenly over the others.

    :raises ValueError: ``n_chunks`` is not between 1 and ``n_items``, or ``first_fewer`` < 0.
    """
    if first_fewer < 0:
        raise ValueError(f"first_fewer must be 0 or more, got {first_fewer}")
    even = split_evenly(n_items, n_chunks)
    first = max(len(even[0]) - first_fewer, 1)
    if n_chunks == 1 or first == len(even[0]):
        return even
    return [range(0, first), *(range(first + chunk.start, first + chunk.stop)
                               for chunk in split_evenly(n_items - first, n_chunks - 1))]


def _idle_work_of(env: gym.Env) -> Optional[Callable[[], bool]]:
    """The ``idle_work`` method of the first wrapper round ``env`` that has one (None: none has)."""
    while env is not None:
        if callable(getattr(type(env), "idle_work", None)):
            return env.idle_work
        env = getattr(env, "env", None)
    return None


class _ChunkVecEnv(DummyVecEnv):
    """A chunk's ``DummyVecEnv`` whose step hands back the infos as they are.

    SB3's deep-copies every step's infos (0.26 ms per step of eight environments in a profile
    of reach training, about 6 % of it) against the same dicts being changed later; here they cannot
    be: every environment step makes new ones, and this returns a new list of them. Otherwise
    the same step (automatic reset, ``terminal_observation``, ``TimeLimit.truncated``), which
    the tests check against ``DummyVecEnv`` itself.
    """

    def __init__(self, env_fns: List[Callable[[], gym.Env]]) -> None:
        super().__init__(env_fns)
        # Deferred work the environments' wrappers offer (`idle_work()`: one unit, False when
        # none is left), e.g. the curriculum's next start prepared in a spare environment.
        self._idle_work = [work for work in map(_idle_work_of, self.envs) if work is not None]
        self.has_idle_work = bool(self._idle_work)  # without any, the processes do not even poll

    def idle_work(self) -> bool:
        """One unit of the environments' deferred work; False when none of them has any."""
        for work in self._idle_work:
            if work():
                return True
        return False

    def step_wait(self):
        for index in range(self.num_envs):
            observation, self.buf_rews[index], terminated, truncated, info = self.envs[index].step(self.actions[index])
            self.buf_dones[index] = terminated or truncated
            info["TimeLimit.truncated"] = truncated and not terminated
            if self.buf_dones[index]:
                info["terminal_observation"] = observation
                observation, self.reset_infos[index] = self.envs[index].reset()
            self.buf_infos[index] = info
            self._save_obs(index, observation)
        return self._obs_from_buf(), np.copy(self.buf_rews), np.copy(self.buf_dones), list(self.buf_infos)


def _answer(venv: DummyVecEnv, command: str, data: Any) -> Any:
    """What a chunk answers to one command (the same in a worker and in the trainer's process)."""
    from stable_baselines3.common.env_util import is_wrapped

    if command == "step":
        observations, rewards, dones, infos = venv.step(data)
        return observations, rewards, dones, infos, venv.reset_infos
    if command == "reset":
        venv._seeds, venv._options = list(data[0]), list(data[1])
        observations = venv.reset()
        return observations, venv.reset_infos
    if command == "get_attr":
        return venv.get_attr(data[0], data[1])
    if command == "has_attr":
        return venv.has_attr(data)
    if command == "set_attr":
        return venv.set_attr(data[0], data[1], data[2])
    if command == "env_method":
        name, args, kwargs, indices = data
        return venv.env_method(name, *args, indices=indices, **kwargs)
    if command == "is_wrapped":
        return [is_wrapped(venv.envs[i], data[0]) for i in data[1]]
    # Returned, not raised: every chunk answers each message, so the pipes stay in step; the
    # trainer raises it (_raise_error) after reading all answers.
    return NotImplementedError(f"ChunkedSubprocVecEnv: unknown command {command!r}")


def _worker(remote, parent_remote, factories: CloudpickleWrapper) -> None:
    """One worker process: a DummyVecEnv of its chunk, driven by (command, data) messages."""
    parent_remote.close()
    venv = _ChunkVecEnv(factories.var)
    while True:
        # Until the trainer's next message, the environments' deferred work (the trainer runs
        # the policy, or an update, meanwhile; or its own chunk is slower).
        while venv.has_idle_work and not remote.poll() and venv.idle_work():
            pass
        try:
            command, data = remote.recv()
        except (EOFError, KeyboardInterrupt):
            break
        if command == "close":
            venv.close()
            remote.close()
            break
        try:
            remote.send(_answer(venv, command, data))
        except Exception as error:  # the trainer raises it; the worker lives on
            remote.send(error)


class _LocalChunk:
    """The chunk stepped in the trainer's process, behind the same (command, data) interface
    as a worker's pipe: ``send`` does the work, ``recv`` hands back the answer."""

    def __init__(self, factories: List[Callable[[], gym.Env]]) -> None:
        self.venv = _ChunkVecEnv(factories)
        self._answer: Any = None

    def send(self, message: Tuple[str, Any]) -> None:
        try:
            self._answer = _answer(self.venv, *message)
        except Exception as error:  # as a worker does: raised once every chunk has answered
            self._answer = error

    def recv(self) -> Any:
        answer, self._answer = self._answer, None
        return answer

    def close(self) -> None:
        pass


def _raise_error(answer: Any) -> Any:
    if isinstance(answer, Exception):
        raise answer
    return answer


def _receive_all(remotes: Sequence[Any]) -> List[Any]:
    """Every chunk's answer, then the first error among them raised: reading them all first
    keeps each pipe in step with its messages."""
    answers = [remote.recv() for remote in remotes]
    return [_raise_error(answer) for answer in answers]


class ChunkedSubprocVecEnv(VecEnv):
    """``len(env_fns)`` environments in ``n_chunks`` even chunks: the first in this process,
    each other one in a worker process.

    :param env_fns: one picklable constructor per environment (index = rank).
    :param n_chunks: how many chunks, i.e. cores used while stepping (>= 2; the trainer's own
        process counts as one).
    :param start_method: ``forkserver`` or ``spawn`` (``fork`` is unsafe next to torch's threads).
    :param trainer_fewer: environments fewer in the trainer's own chunk than an even split gives
        it, spread over the workers' chunks (:func:`split_with_lighter_first`). Speed only: each
        environment steps the same wherever it runs.
    """

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], n_chunks: int,
                 start_method: str = "forkserver", trainer_fewer: int = 0) -> None:
        self.chunks = split_with_lighter_first(len(env_fns), n_chunks, trainer_fewer)
        if n_chunks < 2:
            raise ValueError("ChunkedSubprocVecEnv needs at least 2 chunks; use DummyVecEnv for one")
        context = mp.get_context(start_method)
        self.processes = []
        workers = []
        for chunk in self.chunks[1:]:
            parent, child = context.Pipe()
            process = context.Process(target=_worker, daemon=True,  # a crashed trainer takes its workers along
                                      args=(child, parent, CloudpickleWrapper([env_fns[i] for i in chunk])))
            process.start()
            self.processes.append(process)
            child.close()
            workers.append(parent)
        self.local = _LocalChunk([env_fns[i] for i in self.chunks[0]])
        self.remotes: List[Any] = [self.local, *workers]
        self.waiting, self.closed = False, False
        super().__init__(len(env_fns), self.local.venv.observation_space, self.local.venv.action_space)

    def _all(self, messages: Sequence[Tuple[str, Any]]) -> List[Any]:
        """One message per chunk; the workers' go out first so they run alongside the local chunk."""
        for remote, message in list(zip(self.remotes, messages))[1:]:
            remote.send(message)
        self.local.send(messages[0])
        return _receive_all(self.remotes)

    # -- stepping ---------------------------------------------------------------------------
    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions
        for remote, chunk in zip(self.remotes[1:], self.chunks[1:]):
            remote.send(("step", actions[chunk.start:chunk.stop]))
        self.waiting = True

    def step_wait(self):
        # The local chunk steps while the workers step theirs (sent in step_async).
        self.local.send(("step", self._actions[self.chunks[0].start:self.chunks[0].stop]))
        self.waiting = False
        # While a worker is still stepping, this process does its own environments' deferred work.
        workers, local = self.remotes[1:], self.local.venv
        while local.has_idle_work and not all(worker.poll() for worker in workers) and local.idle_work():
            pass
        results = _receive_all(self.remotes)
        self.reset_infos = [info for result in results for info in result[4]]
        return (np.concatenate([r[0] for r in results]), np.concatenate([r[1] for r in results]),
                np.concatenate([r[2] for r in results]), [info for r in results for info in r[3]])

    def reset(self):
        messages = [("reset", (self._seeds[chunk.start:chunk.stop], self._options[chunk.start:chunk.stop]))
                    for chunk in self.chunks]
        results = self._all(messages)
        self.reset_infos = [info for result in results for info in result[1]]
        self._reset_seeds()
        self._reset_options()
        return np.concatenate([r[0] for r in results])

    def close(self) -> None:
        if self.closed:
            return
        if self.waiting:
            for remote in self.remotes[1:]:
                remote.recv()
        for remote in self.remotes[1:]:
            remote.send(("close", None))
        for process in self.processes:
            process.join()
        for remote in self.remotes[1:]:
            remote.close()
        self.local.venv.close()
        self.closed = True

    def get_images(self) -> Sequence[Optional[np.ndarray]]:
        return [None] * self.num_envs  # the FR5 environments render through the ROS nodes, not here

    # -- attributes and methods, routed to the process that holds each environment -----------
    def _by_process(self, indices: VecEnvIndices) -> List[Tuple[int, List[int]]]:
        """(chunk, local indices) pairs covering ``indices``, in the order given."""
        wanted = self._get_indices(indices)
        routed: List[Tuple[int, List[int]]] = []
        for index in wanted:
            process = next(p for p, chunk in enumerate(self.chunks) if index in chunk)
            local = index - self.chunks[process].start
            if routed and routed[-1][0] == process:
                routed[-1][1].append(local)
            else:
                routed.append((process, [local]))
        return routed

    def _ask(self, indices: VecEnvIndices, make_message: Callable[[List[int]], Tuple[str, Any]]) -> List[Any]:
        routed = self._by_process(indices)
        answers: List[Any] = []
        for process, local in routed:  # one at a time: a chunk may appear twice for unordered indices
            self.remotes[process].send(make_message(local))
            answer = _raise_error(self.remotes[process].recv())
            answers.extend(answer if isinstance(answer, list) else [answer])
        return answers

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> List[Any]:
        return self._ask(indices, lambda local: ("get_attr", (attr_name, local)))

    def has_attr(self, attr_name: str) -> bool:
        return all(self._all([("has_attr", attr_name)] * len(self.chunks)))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._ask(indices, lambda local: ("set_attr", (attr_name, value, local)))

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> List[Any]:
        return self._ask(indices, lambda local: ("env_method", (method_name, method_args, method_kwargs, local)))

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> List[bool]:
        return self._ask(indices, lambda local: ("is_wrapped", (wrapper_class, local)))
