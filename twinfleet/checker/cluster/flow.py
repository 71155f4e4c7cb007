"""The relaxed-order search: workers that expand without waiting for each other (sans-IO).

A level-by-level search makes every worker wait at each level for the slowest one
and for a round trip to the shards, which costs more than a level of a few dozen
worlds takes to expand. Where the order does not matter (no `--search bfs` asked,
no depth bound, no reduction, no checkpoint), each worker runs a `FlowCore`
instead: it owns one partition of the visited set itself, takes batches of
frontier worlds from its own queue, answers the claims on its own partition at
once and sends the others to their owners without waiting, and keeps a batch's
worlds aside (`pending`) until their owner's answer arrives. Every world is still
kept by exactly one worker (the first claim its owner sees) and expanded exactly
once, so the states and transitions are those of the strict BFS; the depth of a
world is the length of the path it was found on, which can exceed its BFS depth.

The search is over when every worker is idle (`FlowStatus.idle`) and every message
sent was received, seen the same twice in a row (Mattern's four counters: a
message in flight between two reads shows as a changed count).

`FlowCore` has no locks and does no I/O: `checker.cluster.engine.FlowWorker` runs
one on its own thread beside the calls that bring claims and answers, and
`LocalFlow` runs several in this process, delivering their messages in a shuffled
order (tests).
"""

from __future__ import annotations

import random
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from itertools import chain, islice
from typing import Protocol, final

import numpy as np

from twinfleet.checker.cluster.level import (
    Acceptance,
    Expander,
    Expansion,
    Failure,
    Graph,
    Item,
    ShardCore,
    owner,
    split,
)
from twinfleet.checker.cluster.visited import VisitedTable
from twinfleet.checker.properties import PropertySet, PropertyViolation
from twinfleet.checker.system import System
from twinfleet.checker.world import World, earliest_time

BATCH = 256  # frontier worlds expanded between two looks at the messages
ASK = 0  # the batch number of a question for worlds and of its answer (claims count from 1)
FORGET_EVERY = 64  # turns of the loop between two passes dropping outcomes no world can use


@final
@dataclass(frozen=True, slots=True)
class Claims:
    """A batch of claims for the worker owning them: keys then parent keys (`pack_pairs`)."""

    target: int
    batch: int  # the sender's number for the batch, echoed in the answer
    blob: bytes


@final
@dataclass(frozen=True, slots=True)
class FlowStatus:
    """What a worker has done so far, read by the coordinator."""

    queue: int  # frontier worlds not yet expanded
    idle: bool  # nothing to expand, no answer left to keep, no turn of the loop under way
    sent: int  # claim batches, answers, questions for worlds and their answers sent
    received: int  # the same, received
    new: int
    transitions: int
    claims: int  # claims sent to other workers
    depth: int
    handler_runs: int
    violation: tuple[PropertyViolation, int, int] | None
    failure: Failure | None
    gifts: int  # answers with worlds this worker got when it asked for some
    gifted: int  # their worlds


@final
class FlowCore:
    """One worker of the relaxed-order search (module docstring): worker `index` of
    `workers`, owning the keys `owner` gives it."""

    def __init__(self, system: System, properties: PropertySet, index: int, workers: int,
                 batch: int = BATCH) -> None:
        self.expander = Expander(system, properties, workers)
        self.index, self.workers, self.batch = index, workers, batch
        self.shard = ShardCore()
        self.queue: deque[Item] = deque()
        self.pending: dict[int, list[tuple[World, int]]] = {}  # batch number -> claimed worlds
        self.answers: list[tuple[int, bytes]] = []  # arrived, kept at the next `next_batch`
        self.kept = Acceptance()
        self.failure: Failure | None = None
        self.transitions = self.claims = self.sent = self.received = 0
        self.busy = False  # between `arrived` and `finish`
        self.asking = self.refused = False  # a question for worlds out; the last refused
        self.gifts = self.gifted = 0  # answers with worlds, and their worlds
        self._batches = self._turns = self._asked = 0

    # ---------------------------------------------------------- the worker's own loop
    # A worker's loop calls, in turn: `arrived`, `keep_answers`, `next_batch`, `expand`,
    # `settle`, `keep_own`, `finish`. Where messages arrive on other threads, `arrived`,
    # `settle` and `finish` (and every message) need the worker's lock; the rest
    # (expansion, property checks: the long parts) touch only what the loop owns, or the
    # queue by single pops and appends (each one step for the interpreter). From
    # `arrived` to `finish` the worker is busy even when its queue is empty: the worlds
    # it holds are in neither.

    def arrived(self) -> list[tuple[int, bytes]]:
        """The answers that arrived since the last call; the worker is busy until `finish`."""
        answers, self.answers = self.answers, []
        self.busy = True
        return answers

    def keep_answers(self, answers: list[tuple[int, bytes]]) -> None:
        """Keep the worlds that answers say are new (into the queue)."""
        for batch, mask in answers:
            self.expander.keep(self.pending.pop(batch), mask, self.kept, self.queue)

    def next_batch(self) -> Iterator[Item]:
        """Up to `batch` worlds to expand, the oldest first (the search stays close to
        breadth-first and so to the outcome cache's times), taken from the queue one by
        one as `expand` reaches them: a worker asking for worlds meanwhile (`spare`) gets
        half of what is left, and a narrow frontier still takes one turn of the loop
        (each has a cost of its own)."""
        queue = self.queue
        for _ in range(self.batch):
            try:
                yield queue.popleft()  # one step, as `spare`'s pops on another thread
            except IndexError:
                return

    def expand(self, batch: Iterable[Item]) -> tuple[Expansion, list[bytes]]:
        """Expand a batch (touches the system, not the partition; the queue only by the
        batch's pops)."""
        return self.expander.expand(None, items=batch)

    def settle(self, expansion: Expansion, blobs: list[bytes]
               ) -> tuple[tuple[list[tuple[World, int]], bytes] | None, list[Claims]]:
        """Answer the batch's claims on this worker's own partition, for `keep_own`; return
        them, and the claims for the other workers (their worlds wait in `pending`)."""
        self.transitions += expansion.transitions
        if expansion.failure is not None and self.failure is None:
            self.failure = expansion.failure
        own, out = None, []
        for target, (worlds, blob) in enumerate(zip(self.expander.pending, blobs, strict=True)):
            if not worlds:
                continue
            if target == self.index:
                own = (worlds, self.shard.claim([blob])[0])
                continue
            self._batches += 1
            self.pending[self._batches] = worlds
            self.claims += len(worlds)
            self.sent += 1
            out.append(Claims(target, self._batches, blob))
        self.expander.pending = []
        return own, out

    def keep_own(self, own: tuple[list[tuple[World, int]], bytes] | None) -> None:
        """Keep the new worlds among the batch's claims on this worker's own partition."""
        if own is not None:
            self.expander.keep(*own, self.kept, self.queue)

    def finish(self) -> None:
        """The end of a turn of the loop: idle again (unless the queue holds worlds); now
        and then, drop cached outcomes that no world left here can use."""
        self.busy = False
        self._turns += 1
        if self._turns % FORGET_EVERY:
            return
        due = earliest_time(chain((w for w, _, _ in self.queue),
                                 (w for worlds in self.pending.values() for w, _ in worlds)))
        if due is not None:
            self.expander.forget_before(due)

    # ------------------------------------------------------------ messages arriving

    def claim(self, blob: bytes) -> bytes:
        """Another worker's claims on this partition: the new/seen mask to send back."""
        self.received += 1
        self.sent += 1
        self.refused = False  # the sender is expanding: it may have worlds to spare
        return self.shard.claim([blob])[0]

    def answered(self, batch: int, mask: bytes) -> None:
        """The owner's answer to one of this worker's claim batches (kept by the loop)."""
        self.received += 1
        self.answers.append((batch, mask))

    def ask(self) -> int | None:
        """The worker to ask for worlds, when this one is idle, has no question out and
        was not refused since it last saw a claim (a worker that is expanding sends
        claims; asking an idle one again and again would keep the counters moving and
        the search from ever ending); else None."""
        if self.asking or self.refused or self.queue or self.answers or self.workers < 2:
            return None
        self.asking = True
        self.sent += 1
        self._asked = (self._asked + 1) % self.workers
        if self._asked == self.index:
            self._asked = (self._asked + 1) % self.workers
        return self._asked

    def spare(self) -> list[Item]:
        """Another worker asked: half this queue (the newest worlds), maybe none."""
        self.received += 1
        self.sent += 1
        queue = self.queue
        spared = []
        for _ in range(len(queue) // 2):
            try:
                spared.append(queue.pop())
            except IndexError:  # the loop's batch took the rest meanwhile
                break
        return spared

    def given(self, worlds: Sequence[Item]) -> None:
        """The answer to `ask`: worlds to expand, or none (refused)."""
        self.received += 1
        self.asking = False
        self.refused = not worlds
        self.queue.extend(worlds)
        self.gifts += bool(worlds)
        self.gifted += len(worlds)

    def load(self, worlds: Sequence[Item], keys: np.ndarray, parents: np.ndarray) -> None:
        """Worlds and this partition's part of the visited set (keys and parent keys) of a
        search handed over."""
        self.queue.extend(worlds)
        self.shard.add(keys, parents)

    # ------------------------------------------------------------------ reading

    def status(self) -> FlowStatus:
        """The counters (`FlowStatus`)."""
        k = self.kept
        idle = not self.queue and not self.answers and not self.busy
        return FlowStatus(len(self.queue), idle, self.sent,
                          self.received, k.new, self.transitions, self.claims, k.depth,
                          self.expander.system.runner.handler_runs, k.violation, self.failure,
                          self.gifts, self.gifted)

    @property
    def graph(self) -> Graph | None:
        """What this worker saw of the graph (`eventually` properties)."""
        return self.expander.graph


@final
class LocalFlow:
    """`FlowCore`s in this process, stepped in turn, their messages delivered in a
    shuffled order, and a turn of a worker's loop now and then left half done while the
    coordinator reads the counters (as a worker's status is read while its loop runs):
    the relaxed-order search without processes, for tests."""

    def __init__(self, system: System, properties: PropertySet, workers: int,
                 seed: int = 0, batch: int = 7, late: int = 0) -> None:
        self.workers = workers
        self.late = late  # polls of `ready` that say no (workers still starting)
        self.cores = [FlowCore(system, properties, i, workers, batch) for i in range(workers)]
        self._random = random.Random(seed)
        self._mail: list[tuple[int, Claims]] = []  # (sender, claims) in flight
        # (receiver, batch, mask or spared worlds) in flight
        self._answers: list[tuple[int, int, bytes | list[Item]]] = []
        self._halfway: dict[int, tuple[list[tuple[int, bytes]], Iterator[Item]]] = {}

    def ready(self) -> bool:
        """`FlowBackend.ready`: no for the first `late` polls."""
        self.late -= 1
        return self.late < 0

    def load(self, frontier: list[Item], visited: VisitedTable) -> None:
        """`FlowBackend.load`."""
        for i, (core, part) in enumerate(zip(self.cores, split(visited, self.workers),
                                             strict=True)):
            core.load(frontier[i::self.workers], *part)

    def advance(self, seconds: float) -> None:
        """`FlowBackend.advance`: one round of one batch per worker, then some messages
        delivered (`seconds` does not matter here)."""
        for i, core in enumerate(self.cores):
            answers, batch = self._halfway.pop(i) if i in self._halfway else \
                (core.arrived(), core.next_batch())
            if self._random.random() < 0.2:  # answers taken, the batch begun, the rest later
                self._halfway[i] = (answers, self._begun(batch))
                continue
            core.keep_answers(answers)
            own, out = core.settle(*core.expand(batch))
            core.keep_own(own)
            self._mail += [(i, c) for c in out]
            core.finish()
            if (peer := core.ask()) is not None:
                self._mail.append((i, Claims(peer, ASK, b"")))
        self._deliver()

    def _begun(self, batch: Iterator[Item]) -> Iterator[Item]:
        """`batch` with a random number of its worlds taken already (as a worker's loop
        takes them while questions for worlds arrive)."""
        taken = list(islice(batch, self._random.randint(0, 3)))
        return chain(taken, batch)

    def _deliver(self) -> None:
        """Deliver a random part of the messages in flight, in a random order."""
        rng = self._random
        rng.shuffle(self._mail)
        rng.shuffle(self._answers)
        cut, keep = rng.randint(0, len(self._mail)), rng.randint(0, len(self._answers))
        for sender, claims in self._mail[:cut]:
            target = self.cores[claims.target]
            answer = target.spare() if claims.batch == ASK else target.claim(claims.blob)
            self._answers.append((sender, claims.batch, answer))
        self._mail = self._mail[cut:]
        for receiver, batch, answer in self._answers[:keep]:
            if isinstance(answer, bytes):
                self.cores[receiver].answered(batch, answer)
            else:
                self.cores[receiver].given(answer)
        self._answers = self._answers[keep:]

    def status(self) -> list[FlowStatus]:
        """`FlowBackend.status`."""
        return [core.status() for core in self.cores]

    def lineage(self, key: int) -> list[int]:
        """`FlowBackend.lineage`."""
        index = owner(key, self.workers)
        return self.cores[index].shard.lineage(key, index, self.workers)

    def shard_bytes(self) -> list[int]:
        """`FlowBackend.shard_bytes`."""
        return [core.shard.nbytes() for core in self.cores]

    def graphs(self) -> list[Graph]:
        """`FlowBackend.graphs`."""
        return [core.graph for core in self.cores if core.graph is not None]

    def visited(self) -> list[bytes]:
        """`FlowBackend.visited`."""
        return [core.shard.dump() for core in self.cores]

    def stop(self) -> None:
        """`FlowBackend.stop`: nothing runs on its own here."""


class FlowBackend(Protocol):
    """Where a relaxed-order search runs: `LocalFlow`, or Ray workers
    (`checker.cluster.engine.RayFlow`)."""

    workers: int

    def ready(self) -> bool:
        """Whether every worker is up (raises ClusterError if one cannot start)."""
        ...

    def load(self, frontier: list[Item], visited: VisitedTable) -> None:
        """Take over a search begun in the coordinator, and start."""
        ...

    def advance(self, seconds: float) -> None:
        """Let the workers run for about `seconds` (raises ClusterError if one failed)."""
        ...

    def status(self) -> list[FlowStatus]:
        """Every worker's counters."""
        ...

    def lineage(self, key: int) -> list[int]:
        """The parent of a visited key and its ancestors, one call's worth
        (`ShardCore.lineage`): ends with ROOT or with a key to ask about next."""
        ...

    def shard_bytes(self) -> list[int]:
        """Bytes held per partition."""
        ...

    def graphs(self) -> list[Graph]:
        """What every worker saw of the graph (`eventually` properties), at the end."""
        ...

    def visited(self) -> list[bytes]:
        """Every partition's keys and parents (`ShardCore.dump`), at the end."""
        ...

    def stop(self) -> None:
        """Stop the workers' loops."""
        ...
