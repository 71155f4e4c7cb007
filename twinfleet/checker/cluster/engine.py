"""The one module of the checker that imports Ray: actors, the cluster backend, the engine.

`connect` joins a cluster as this process's driver: a local one of
`checker.cluster.head.LocalHead` (loopback, no dashboard nor usage statistics) or
one of other machines. `session(workers, address)` does it all for a caller that
waits (the statistical engine), and stops what it started; a Ray already initialised
by the caller (a test's shared cluster) is used as it is. `RayBackend` runs the levels of
`checker.cluster.coordinator` on `Worker` actors (an `Expander` each) and
`Shard` actors (a `ShardCore` each): claims go from workers to shards and
masks back as object references, so the coordinator moves no claim itself.
`RayFlow` runs a relaxed-order search (`checker.cluster.flow`) on `FlowWorker` actors
that send each other claims and answers directly. `RayEngine`: `checker.parallel.Engine`.
"""

from __future__ import annotations

import logging
import os
import pickle
import re
import secrets
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any, final

import numpy as np

from twinfleet.checker.cluster.flow import ASK, FlowCore, FlowStatus
from twinfleet.checker.cluster.head import local_head
from twinfleet.checker.cluster.level import (
    Acceptance,
    Expander,
    Expansion,
    Graph,
    Item,
    ShardCore,
    owner,
    split,
)
from twinfleet.checker.cluster.links import TOKEN_BYTES, Links
from twinfleet.checker.cluster.ray_host import answers, ray_notices, worker_env
from twinfleet.checker.cluster.spec import ClusterError, SystemSpec, fingerprint, mismatch
from twinfleet.checker.cluster.visited import VisitedTable
from twinfleet.checker.collector import Held, quick_switches, seldom_collections
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.reduction import Reduction
from twinfleet.checker.system import System

try:
    import ray
    from ray.exceptions import RayError
except ImportError:  # pragma: no cover - exercised in a subprocess without Ray
    raise ClusterError("the distributed search needs Ray: pip install twinfleet[cluster]") \
        from None


def connect(address: str, log: str, *, local: bool) -> None:
    """Join the cluster at `address` as this process's driver, Ray's own log lines (its
    notices) going to the file `log` rather than to the terminal. `local`: a `head.LocalHead` of this process,
    whose workers inherit the node code's path from the cluster's processes (with a
    job's runtime_env instead, Ray starts a new process for every actor rather than
    using the ones it keeps ready: two actors up in 1.0-1.2 s against 0.2-0.5 s); a
    cluster of other machines gets the path as the job's environment."""
    handler = logging.FileHandler(log)
    _log_to(handler, "ray._private")  # where ray.init's own messages come from
    try:
        if local:
            ray.init(address=address, log_to_driver=False, configure_logging=False)
        else:
            ray.init(address=address, log_to_driver=False, configure_logging=False,
                     runtime_env={"env_vars": worker_env()})
        _log_to(handler, "ray")  # ray.init without configure_logging empties its handlers
    except Exception as exc:  # noqa: BLE001 - Ray raises many types for one bad address
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        where = "the local cluster" if local else f"cluster {address}"
        raise ClusterError(f"cannot connect to {where}: {first} (a cluster started with `ray "
                           f"start --head` needs the same RAY_AUTH_TOKEN here; Ray's log: {log})"
                           ) from None
    finally:  # ray._private propagates to the ray logger again: one place to redirect
        _log_to(None, "ray._private")


def _log_to(handler: logging.Handler | None, name: str) -> None:
    logger = logging.getLogger(name)  # None: Ray's setting back (no handler, propagating)
    logger.handlers, logger.propagate = ([], True) if handler is None else ([handler], False)


def disconnect() -> None:
    """Leave the cluster `connect` joined."""
    ray.shutdown()


@contextmanager
def session(workers: int, address: str | None) -> Iterator[None]:
    """A Ray connection for the command (module docstring), waiting for a local cluster
    to start; ClusterError if none."""
    if ray.is_initialized():
        yield
        return
    head = local_head(workers) if address is None else None
    try:
        with ray_notices():  # what Ray's C++ core writes to file descriptor 2 as well
            if head is None:
                assert address is not None
                answers(address)
                connect(address, os.devnull, local=False)
            else:
                head.wait_up()
                connect(head.address, head.driver_log, local=True)
        try:
            yield
        finally:
            with ray_notices():
                disconnect()
    finally:
        if head is not None:
            head.stop()


def _built(spec: SystemSpec, expected: dict[str, str], actor: Held
           ) -> tuple[System, PropertySet, Reduction | None]:
    """The system, properties and reduction of `spec`, built here (the search's collector
    thresholds held by `actor` until it is released); ClusterError when this machine's
    scenario, rules or node sources differ from the coordinator's (`expected`)."""
    actor.hold(seldom_collections())
    system, props, reduction = spec.build()
    differs = mismatch(fingerprint(system), expected)
    if differs is not None:
        raise ClusterError(f"worker on {os.uname().nodename}: its {differs} differ(s) "
                           "from the coordinator's")
    return system, props, reduction


@ray.remote(num_cpus=1)
class Worker(Held):
    """An `Expander` on a system built from a `SystemSpec`."""

    def __init__(self, spec: SystemSpec, expected: dict[str, str], shards: int) -> None:
        system, props, reduction = _built(spec, expected, self)
        self.core = Expander(system, props, shards, reduction)

    def propose(self, max_depth: int | None) -> tuple[Any, ...]:
        """`Expander.propose`, a count then one return value per shard blob."""
        return (0, *self.core.propose(max_depth))

    def expand(self, max_depth: int | None, *stored: bytes) -> tuple[Any, ...]:
        """`Expander.expand` (`stored`: the shards' answers to `propose`), one return
        value per shard blob."""
        expansion, blobs = self.core.expand(max_depth, list(stored) if stored else None)
        return (expansion, *blobs)

    def relearn(self, relation: tuple[Any, ...] | None) -> int:
        """`Expander.relearn` (an unreduced search: an empty frontier only)."""
        if relation is None:
            self.core.frontier = []
        else:
            self.core.relearn(relation)
        return 0

    def accept(self, *masks: bytes) -> Acceptance:
        """`Expander.accept`; then drop cached outcomes the frontier cannot use."""
        out = self.core.accept(list(masks))
        if out.min_due is not None:
            self.core.forget_before(out.min_due)
        return out

    def give(self, count: int) -> bytes:
        """`Expander.give`."""
        return self.core.give(count)

    def take(self, blob: bytes) -> int:
        """`Expander.take`."""
        return self.core.take(blob)

    def packed(self) -> bytes:
        """`Expander.packed`."""
        return self.core.packed()

    def graph(self) -> bytes:
        """The worker's graph records (`Expander.graph`), pickled."""
        return pickle.dumps(self.core.graph, protocol=pickle.HIGHEST_PROTOCOL)


# Ray's typed overloads of `remote` do not list this (real, documented) actor option.
@ray.remote(num_cpus=0, allow_out_of_order_execution=True)  # type: ignore[call-overload]
class Shard:
    """A `ShardCore`. Its calls run as soon as their arguments are ready, not in the order
    they were made (a worker's questions need not wait behind another's): every call
    that must follow another depends on its result, or the coordinator waited for it."""

    def __init__(self) -> None:
        self.core = ShardCore()

    def claim(self, *blobs: bytes) -> tuple[Any, ...]:
        """`ShardCore.claim`, one mask per worker after a count (never read: it keeps the
        number of return values above one, which Ray returns as a list)."""
        masks = self.core.claim(list(blobs))
        return (len(self.core.visited), *masks)

    def stored(self, *blobs: bytes) -> tuple[Any, ...]:
        """`ShardCore.stored`, a count then one mask per worker."""
        return (0, *self.core.stored(list(blobs)))

    def clear(self) -> int:
        """`ShardCore.clear`."""
        self.core.clear()
        return 0

    def drain(self) -> bytes:
        """`ShardCore.drain`."""
        return self.core.drain()

    def add(self, keys: np.ndarray, parents: np.ndarray) -> int:
        """`ShardCore.add`."""
        self.core.add(keys, parents)
        return len(self.core.visited)

    def lineage(self, key: int, index: int, shards: int) -> list[int]:
        """`ShardCore.lineage`."""
        return self.core.lineage(key, index, shards)

    def nbytes(self) -> int:
        """`ShardCore.nbytes`."""
        return self.core.nbytes()

    def dump(self) -> bytes:
        """`ShardCore.dump`."""
        return self.core.dump()


# Four threads: the loop, and the coordinator's calls (Ray's typed overloads of `remote`
# do not list the actor option); the links read on threads of their own.
@ray.remote(num_cpus=1, max_concurrency=4)  # type: ignore[call-overload]
class FlowWorker(Held):
    """A `FlowCore` whose loop (`run`) expands on one thread while claims, answers (over
    `Links`) and moved worlds arrive on others; one lock guards the core's shared parts,
    and only the loop touches the system (expansion, property checks, outcome cache)."""

    def __init__(self, spec: SystemSpec, expected: dict[str, str], index: int,
                 workers: int, token: bytes) -> None:
        system, props, _ = _built(spec, expected, self)
        self.core = FlowCore(system, props, index, workers)
        self.lock = threading.Condition()
        self.stopped = False
        host = ray.util.get_node_ip_address()  # type: ignore[no-untyped-call]
        self.links = Links(index, host, token, self._claims, self._answered)
        # A claim's answer waits for the loop to let go of the interpreter: 5 ms by default,
        # more than the rest of the round trip; 50 µs while this worker works.
        self.hold(quick_switches(0.00005))

    def address(self) -> tuple[str, int]:
        """Where this worker's links listen."""
        return self.links.address

    def meet(self, addresses: list[tuple[str, int]]) -> int:
        """Connect to every other worker (`Links.connect`)."""
        self.links.connect(addresses)
        return 0

    def load(self, blob: bytes, keys: np.ndarray, parents: np.ndarray) -> int:
        """`FlowCore.load`: pickled worlds and this partition's keys and parents."""
        with self.lock:
            self.core.load(pickle.loads(blob), keys, parents)  # noqa: S301 - the coordinator
        return 0

    def run(self) -> int:
        """Expand until `stop`, waiting for answers or moved worlds when idle; the lock is
        held only while the core's shared parts change (`FlowCore`'s order)."""
        core, lock, links = self.core, self.lock, self.links
        while True:
            with lock:
                while not self.stopped and not core.queue and not core.answers and \
                        links.error is None:
                    if (peer := core.ask()) is not None:
                        links.claim(peer, ASK, b"")
                    lock.wait(0.05)
                if self.stopped:
                    return 0
                if links.error is not None:
                    raise ClusterError(links.error)
                answers = core.arrived()
            core.keep_answers(answers)
            if core.queue:
                expansion, blobs = core.expand(core.next_batch())
                with lock:
                    own, out = core.settle(expansion, blobs)
                for claims in out:
                    links.claim(claims.target, claims.batch, claims.blob)
                core.keep_own(own)
            with lock:
                core.finish()

    def _claims(self, sender: int, batch: int, blob: bytes) -> bytes:
        if batch != ASK:
            with self.lock:
                answer = self.core.claim(blob)
                self.lock.notify()  # a loop refused worlds may ask again: the sender is busy
                return answer
        with self.lock:
            spared = self.core.spare()
        return pickle.dumps(spared, protocol=pickle.HIGHEST_PROTOCOL)

    def _answered(self, batch: int, answer: bytes) -> None:
        worlds = pickle.loads(answer) if batch == ASK else None  # noqa: S301 - our workers
        with self.lock:
            if worlds is None:
                self.core.answered(batch, answer)
            else:
                self.core.given(worlds)
            self.lock.notify()

    def status(self) -> FlowStatus:
        """`FlowCore.status`."""
        with self.lock:
            return self.core.status()

    def stop(self) -> int:
        """End the loop."""
        with self.lock:
            self.stopped = True
            self.lock.notify()
        return 0

    def unlink(self) -> int:
        """Close the links (once every worker's loop ended: a closed link is otherwise an
        error for the other end)."""
        self.links.close()
        return 0

    def lineage(self, key: int) -> list[int]:
        """`ShardCore.lineage` of this partition."""
        with self.lock:
            return self.core.shard.lineage(key, self.core.index, self.core.workers)

    def nbytes(self) -> int:
        """`ShardCore.nbytes` of this partition."""
        with self.lock:
            return self.core.shard.nbytes()

    def dump(self) -> bytes:
        """`ShardCore.dump` of this partition."""
        with self.lock:
            return self.core.shard.dump()

    def graph(self) -> bytes:
        """The worker's graph records, pickled."""
        with self.lock:
            return pickle.dumps(self.core.graph, protocol=pickle.HIGHEST_PROTOCOL)


_ANSI = re.compile(r"\x1b\[[0-9;]*m")  # Ray colours the names in its messages
_OURS = f"{ClusterError.__module__}.{ClusterError.__name__}: "


def _get(refs: Any) -> Any:
    try:
        return ray.get(refs)
    except RayError as exc:
        text = str(exc).strip()
        if _OURS in text:  # a worker refused (e.g. other node sources): its own words
            raise ClusterError(text.rsplit(_OURS, 1)[1].splitlines()[0]) from None
        first = _ANSI.sub("", text.splitlines()[0]) if text else type(exc).__name__
        raise ClusterError(f"a worker or shard of the cluster failed, no verdict: "
                           f"{type(exc).__name__}: {first}") from None


def _release(actors: list[Any]) -> None:
    """Let workers restore their process's settings (those that answer within a second)."""
    ray.wait([a.release.remote() for a in actors], num_returns=len(actors), timeout=1.0)


def _up(backend: RayBackend | RayFlow, starting: list[Any]) -> bool:
    """Whether the first calls to `backend`'s actors (`starting`) have all returned: the
    actors are up. Raises ClusterError, the actors stopped, when one could not start."""
    done, _ = ray.wait(starting, num_returns=len(starting), timeout=0)
    if len(done) < len(starting):
        return False
    try:
        _get(starting)
    except ClusterError:
        backend.close()
        raise
    return True


@final
class RayBackend:
    """`backend.Backend` on `workers` Worker actors and as many Shard actors."""

    def __init__(self, spec: SystemSpec, expected: dict[str, str], workers: int) -> None:
        self.workers = workers
        self.reduced = spec.reduction is not None
        self._fresh = True  # the workers have not learned the coordinator's relation yet
        self.shards = [Shard.remote() for _ in range(workers)]  # type: ignore[attr-defined]
        self.actors = [Worker.remote(spec, expected, workers)  # type: ignore[attr-defined]
                       for _ in range(workers)]
        self._starting = [a.take.remote(pickle.dumps([])) for a in self.actors]
        self._moves: list[Any] = []  # moves made since the last level (`move`)

    def ready(self) -> bool:
        """`backend.Backend.ready`, without waiting."""
        if self._starting and not _up(self, self._starting):
            return False
        self._starting = []
        return True

    def load(self, frontier: list[Item], visited: VisitedTable,
             relation: tuple[Any, ...] | None = None) -> RayBackend:
        """Take over a search begun in this process: its frontier, visited set and (a
        reduced search) send relation."""
        if relation is not None and self._fresh:  # later loads: the same relation, kept records
            _get([a.relearn.remote(relation) for a in self.actors])
        self._fresh = False
        parts: list[list[Item]] = [frontier[i::self.workers] for i in range(self.workers)]
        refs = [a.take.remote(pickle.dumps(p, protocol=pickle.HIGHEST_PROTOCOL))
                for a, p in zip(self.actors, parts, strict=True)]
        refs += [s.add.remote(*part)
                 for s, part in zip(self.shards, split(visited, self.workers), strict=True)]
        _get(refs)
        return self

    def level(self, max_depth: int | None) -> tuple[list[Expansion], list[Acceptance]]:
        """One level on the cluster (`backend.Backend.level`).

        A reduced level asks each worker's cycle-proviso questions with one call per
        worker and shard, so a worker expands as soon as the shards have answered its
        own questions: the claims are the level's only barrier. A shard answers a
        level's questions before its claims (the claims wait for every expansion, each
        expansion for its answers), so it holds exactly the worlds at most as deep as
        the level then.
        """
        n = self.workers
        stored: list[list[Any]] = [[] for _ in self.actors]
        if self.reduced:  # the cycle proviso's questions first (`Expander.propose`)
            proposed = [a.propose.options(num_returns=n + 1).remote(max_depth)
                        for a in self.actors]
            stored = [[s.stored.options(num_returns=2).remote(proposed[w][k + 1])[1]
                       for k, s in enumerate(self.shards)] for w in range(n)]
        expanded = [a.expand.options(num_returns=n + 1).remote(max_depth, *stored[w])
                    for w, a in enumerate(self.actors)]
        claimed = [s.claim.options(num_returns=n + 1).remote(*[e[k + 1] for e in expanded])
                   for k, s in enumerate(self.shards)]
        accepted = [a.accept.remote(*[c[w + 1] for c in claimed])
                    for w, a in enumerate(self.actors)]
        done = _get([*[e[0] for e in expanded], *accepted, *self._moves])
        self._moves = []
        return done[:n], done[n:2 * n]

    def lineage(self, key: int) -> list[int]:
        """`backend.Backend.lineage`: asks the owning shard."""
        index = owner(key, self.workers)
        return list(_get(self.shards[index].lineage.remote(key, index, self.workers)))

    def shard_bytes(self) -> list[int]:
        """`backend.Backend.shard_bytes`."""
        return list(_get([s.nbytes.remote() for s in self.shards]))

    def move(self, source: int, target: int, count: int) -> None:
        """`backend.Backend.move`: one blob, passed by reference, not waited for here
        (a worker runs its calls in order, so the next level's see the move; its failure
        comes out with that level's answers)."""
        self._moves.append(self.actors[target].take.remote(self.actors[source].give.remote(count)))

    def graphs(self) -> list[Graph]:
        """`backend.Backend.graphs`."""
        found = [pickle.loads(b) for b in _get([a.graph.remote() for a in self.actors])]
        return [g for g in found if g is not None]

    def take_back(self) -> tuple[list[Item], list[bytes]]:
        """`backend.Backend.take_back`: all frontiers given, all shards drained."""
        given = _get([a.give.remote(1 << 62) for a in self.actors])
        visited = _get([s.drain.remote() for s in self.shards])
        return [item for blob in given for item in pickle.loads(blob)], list(visited)

    def reset(self, relation: tuple[Any, ...] | None) -> None:
        """`backend.Backend.reset`: empty frontiers and shards."""
        _get([a.relearn.remote(relation) for a in self.actors] +
             [s.clear.remote() for s in self.shards])
        self._fresh = False

    def snapshot(self) -> tuple[list[bytes], list[bytes]]:
        """`backend.Backend.snapshot`: every worker's frontier and shard's keys."""
        frontier = [a.packed.remote() for a in self.actors]
        visited = [s.dump.remote() for s in self.shards]
        return list(_get(frontier)), list(_get(visited))

    def close(self) -> None:
        """Stop every actor (a cluster that outlives the command keeps none holding a CPU)."""
        _release(self.actors)
        for actor in (*self.actors, *self.shards):
            ray.kill(actor, no_restart=True)

    def kill_shard(self, index: int) -> None:
        """Kill one shard actor (a fault for tests)."""
        ray.kill(self.shards[index], no_restart=True)


@final
class RayFlow:
    """`checker.cluster.flow.FlowBackend` on `workers` FlowWorker actors."""

    def __init__(self, spec: SystemSpec, expected: dict[str, str], workers: int) -> None:
        self.workers = workers
        token = secrets.token_bytes(TOKEN_BYTES)
        self.actors = [FlowWorker.remote(spec, expected, i, workers, token)  # type: ignore[attr-defined]
                       for i in range(workers)]
        self._starting = [a.address.remote() for a in self.actors]
        self._runs: list[Any] = []

    def ready(self) -> bool:
        """`FlowBackend.ready`, without waiting for a worker to start; once all are up,
        they connect to each other."""
        if not self._starting:
            return True
        if not _up(self, self._starting):
            return False
        addresses, self._starting = _get(self._starting), []
        try:
            _get([a.meet.remote(addresses) for a in self.actors])
        except ClusterError:
            self.close()
            raise
        return True

    def load(self, frontier: list[Item], visited: VisitedTable) -> None:
        """`FlowBackend.load`: each worker's share of the frontier and its partition; then
        every loop starts."""
        n = self.workers
        _get([a.load.remote(pickle.dumps(frontier[i::n], protocol=pickle.HIGHEST_PROTOCOL),
                            *part)
              for i, (a, part) in enumerate(zip(self.actors, split(visited, n), strict=True))])
        self._runs = [a.run.remote() for a in self.actors]

    def advance(self, seconds: float) -> None:
        """`FlowBackend.advance`: a loop that ended before `stop` failed."""
        ended, _ = ray.wait(self._runs, timeout=seconds)
        if ended:
            _get(ended)
            raise ClusterError("a worker of the cluster stopped before the search ended, "
                               "no verdict")

    def status(self) -> list[FlowStatus]:
        """`FlowBackend.status`."""
        return list(_get([a.status.remote() for a in self.actors]))

    def lineage(self, key: int) -> list[int]:
        """`FlowBackend.lineage`: asks the owning worker."""
        return list(_get(self.actors[owner(key, self.workers)].lineage.remote(key)))

    def shard_bytes(self) -> list[int]:
        """`FlowBackend.shard_bytes`."""
        return list(_get([a.nbytes.remote() for a in self.actors]))

    def graphs(self) -> list[Graph]:
        """`FlowBackend.graphs`."""
        found = [pickle.loads(b) for b in _get([a.graph.remote() for a in self.actors])]
        return [g for g in found if g is not None]

    def visited(self) -> list[bytes]:
        """`FlowBackend.visited`."""
        return list(_get([a.dump.remote() for a in self.actors]))

    def stop(self) -> None:
        """`FlowBackend.stop`: every loop ended (a failed one says so)."""
        _get([a.stop.remote() for a in self.actors])
        try:
            _get(self._runs)
        finally:
            _get([a.unlink.remote() for a in self.actors])

    def close(self) -> None:
        """Stop every actor of this search."""
        _release(self.actors)
        for actor in self.actors:
            ray.kill(actor, no_restart=True)


@ray.remote
def _run_batch(batch_fn: Any, batch: list[int]) -> list[Any]:
    return list(batch_fn(batch))


@final
class RayEngine:
    """`checker.parallel.Engine` on Ray tasks: one task per batch."""

    def __init__(self, workers: int, address: str | None) -> None:
        self.workers = workers
        self._session = session(workers, address)
        self._session.__enter__()

    def map(self, batch_fn: Any, batches: Sequence[list[int]]) -> list[list[Any]]:
        """`batch_fn` on every batch as a Ray task; results in batch order."""
        fn = ray.put(batch_fn)
        return list(_get([_run_batch.remote(fn, b) for b in batches]))

    def close(self) -> None:
        """Leave the cluster (stopping it if this engine started it)."""
        self._session.__exit__(None, None, None)
