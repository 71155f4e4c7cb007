"""The cluster's backend started on a thread of its own while the search goes on.

Importing Ray (about a second of Python on this process's interpreter) and
joining a cluster (seconds while a local one starts) happen on that thread;
the search's thread only asks `Starting.ready` between two levels. A search
that ends while the cluster starts does not wait for it: the thread joins
nothing once closed, and the caller stops the local cluster under it (only a
join already under way, a few seconds once the cluster is up, is waited for).
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable
from typing import Any, final

from twinfleet.checker.cluster.head import LocalHead, driver_env, local_head
from twinfleet.checker.cluster.ray_host import answers
from twinfleet.checker.cluster.spec import ClusterError


def prepare_environment(local: bool) -> None:
    """This process's environment for Ray, set before Ray is first imported (and on the
    main thread: the environment is the whole process's). `local`: the command starts its
    own cluster (`head.driver_env`: Ray reads its cluster switch once, at import: set off,
    a local cluster advertises and binds 127.0.0.1 only, where it would otherwise listen
    on every interface under the host's address; joining a cluster of several machines
    needs the switch on, so only a local cluster sets it)."""
    if local and "ray" not in sys.modules:
        os.environ.update(driver_env())
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # offline: no usage report


def engine_module(local: bool = True) -> Any:
    """`checker.cluster.engine` (imports Ray); ClusterError when Ray is not installed.
    `local`: as `prepare_environment`."""
    prepare_environment(local)
    return _imported()


def _imported() -> Any:
    try:
        from twinfleet.checker.cluster import engine
    except ImportError as exc:
        raise ClusterError("the distributed search needs Ray: pip install "
                           f"twinfleet[cluster] ({exc})") from None
    return engine


def ray_running() -> bool:
    """Whether this process is already connected to a Ray cluster (a test's shared one),
    without importing Ray."""
    ray = sys.modules.get("ray")
    return ray is not None and bool(ray.is_initialized())


@final
class Starting:
    """A backend (`checker.cluster.backend.Backend` or `flow.FlowBackend`) being built on
    a thread of its own: `make(engine)` once this process joined the cluster. Until it is
    built, `ready` is False; then it is the backend's `ready`, and every other attribute
    is the backend's.

    Args:
        workers: the backend's workers.
        make: builds the backend from `checker.cluster.engine` (on the thread).
        head: the local cluster to join once it answers, or None.
        address: a cluster of other machines to join, or None (with no `head` either:
            this process is already connected).
    """

    def __init__(self, workers: int, make: Callable[[Any], Any], head: LocalHead | None,
                 address: str | None) -> None:
        self.workers = workers
        self._make, self._head, self._address = make, head, address
        self._lock = threading.Lock()
        self._closed = False
        self._built: Any = None
        self._engine: Any = None  # the engine module, once this process joined a cluster
        self._error: BaseException | None = None
        self._joining = False  # joining the cluster (`close` then waits for it)
        self._done = threading.Event()  # the thread ended
        prepare_environment(local=head is not None)
        self._thread = threading.Thread(target=self._run, name="cluster-start", daemon=True)
        self._thread.start()

    def ready(self) -> bool:
        """Whether the backend is built and its workers are up; ClusterError if it failed."""
        if self._thread.is_alive():
            return False
        if self._error is not None:
            if isinstance(self._error, ClusterError):
                raise self._error
            raise ClusterError(f"the cluster could not start: {type(self._error).__name__}: "
                               f"{self._error}")
        if not self._built.ready():
            return False
        if self._head is not None:
            self._head.background.restore()  # the workers take the search over from here
        return True

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or self._built is None:
            raise AttributeError(name)
        return getattr(self._built, name)

    def close(self) -> None:
        """Stop the backend's workers and leave the cluster. A start still waiting for the
        cluster is not waited for (it joins nothing once closed); one joining it is, for
        the few seconds joining takes once the cluster is up, since Ray ends a process
        whose cluster stops while it joins."""
        with self._lock:
            self._closed = True
            joining = self._joining
        if joining:
            self._done.wait()
        with self._lock:
            built, engine = self._built, self._engine
        _shut(built, engine)

    def _run(self) -> None:
        engine = built = None
        try:
            if self._head is not None or self._address is not None:
                if self._head is not None:
                    self._head.wait_up()
                engine = _imported()
                with self._lock:
                    if self._closed:
                        engine = None  # joined nothing: nothing to leave
                        return
                    self._joining = True
                if self._head is not None:
                    engine.connect(self._head.address, self._head.driver_log, local=True)
                else:
                    engine.connect(self._address, os.devnull, local=False)
            built = self._make(engine or _imported())
        except BaseException as exc:  # noqa: BLE001 - handed to the search's thread
            self._error = exc
        finally:
            self._keep(built, engine)
            self._done.set()

    def _keep(self, built: Any, engine: Any) -> None:
        with self._lock:
            if not self._closed:
                self._built, self._engine = built, engine
                return
        _shut(built, engine)  # the search ended meanwhile: nobody else will


def _shut(built: Any, engine: Any) -> None:
    if built is not None:
        built.close()
    if engine is not None:
        engine.disconnect()


def start(workers: int, make: Callable[[Any], Any], address: str | None,
          on_stop: Callable[[Callable[[], None]], object], background: bool = False
          ) -> Starting:
    """A `Starting` backend on the cluster the command uses: a Ray this process already
    joined, the cluster at `address`, or a local one started now (its processes stopped
    through `on_stop`, after the backend's `close`, which `on_stop` is given too, in the
    order of an ExitStack's callbacks: last given, first run). `background`: the search
    goes on here meanwhile, so a local cluster starts at low priority until its workers
    are up (`head.Background`)."""
    head: LocalHead | None = None
    running = ray_running()
    if not running:
        if address is None:
            head = local_head(workers)
            on_stop(head.stop)
            if background:
                head.background.lower()
        else:
            answers(address)
    started = Starting(workers, make, head, None if running else address)
    on_stop(started.close)
    return started
