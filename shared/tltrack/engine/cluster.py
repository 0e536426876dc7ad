"""Monte-Carlo batches on a Dask cluster: ``--scheduler ADDRESS`` or ``TLTRACK_SCHEDULER``.

:func:`pool` connects a Dask client to a running scheduler and gives a
:class:`concurrent.futures.Executor` that :func:`tltrack.engine.montecarlo.run_sweep` takes in place
of its local process pool. Without an address it gives ``None``, and the engine keeps its embedded
process pool: no scheduler is ever needed for that.

Results are those of the local pool: every run draws from its own (seed, run, purpose) streams,
and the engine merges batches in batch order whatever order they complete in.

The cluster is never allowed to hang the caller. Connecting gives up after ``connect_timeout``;
a scheduler without workers is waited for ``worker_wait`` at most; while batches are out, a
watchdog asks the scheduler who it is every ``ping_every`` seconds and fails the sweep with a
:class:`SchedulerError` if it does not answer within ``ping_timeout``, or if no worker has been
left for ``worker_wait``. A scheduler that dies closes the client's connection, and the sweep
fails at once. A worker that dies costs only the batches it held: the scheduler runs them again
elsewhere.

Dask moves pickles: whoever can reach the scheduler can run code on the workers. Keep it on a
private network, or use ``tls://`` addresses with Dask's security settings (docs/howto/dask.md,
"Security").
"""

from __future__ import annotations

import asyncio
import logging
import os
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, InvalidStateError
from contextlib import contextmanager, suppress
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from distributed import Client

ENV = "TLTRACK_SCHEDULER"
CONNECT_TIMEOUT_S = 10.0
PING_EVERY_S = 5.0
PING_TIMEOUT_S = 15.0
WORKER_WAIT_S = 120.0

log = logging.getLogger(__name__)


class SchedulerError(RuntimeError):
    """The Dask scheduler could not be reached, stopped answering, or has no workers."""


def address(option: str | None = None) -> str | None:
    """The scheduler to use: ``option``, else ``$TLTRACK_SCHEDULER``; blank means none."""
    value = option if option is not None else os.environ.get(ENV, "")
    return value.strip() or None


def refuse_workers(scheduler: str | None, workers: int | None) -> str | None:
    """Why ``--workers`` cannot go with ``--scheduler``, or None when the two do not clash."""
    if scheduler is None or workers is None:
        return None
    return (
        f"--workers sizes the local process pool, but --scheduler (or {ENV}) sends the batches "
        f"to the Dask cluster at {scheduler}, whose own workers run them: size the cluster with "
        "`dask worker --nworkers N` instead, or drop --scheduler to use the local pool"
    )


class DaskPool(Executor):
    """A :class:`concurrent.futures.Executor` over a Dask client, which never hangs its caller.

    Every ``submit`` is ``pure=False``: two batches with the same arguments are two tasks. The
    futures it returns fail with :class:`SchedulerError` when the scheduler is lost.
    """

    def __init__(
        self,
        client: Client,
        address: str,
        *,
        ping_every: float = PING_EVERY_S,
        ping_timeout: float = PING_TIMEOUT_S,
        worker_wait: float = WORKER_WAIT_S,
    ) -> None:
        self.client = client
        self.address = address
        self._executor = client.get_executor(pure=False)
        self._ping_every = ping_every
        self._ping_timeout = ping_timeout
        self._worker_wait = worker_wait
        self._lock = threading.Lock()
        self._pending: set[Future[Any]] = set()
        self._error: SchedulerError | None = None
        self._stop = threading.Event()
        self._watchdog = threading.Thread(target=self._watch, name="tltrack-dask-watchdog")
        self._watchdog.daemon = True
        self._watchdog.start()

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        if self._error is not None:
            raise self._error
        out: Future[Any] = Future()
        with self._lock:
            self._pending.add(out)
        inner = self._executor.submit(fn, *args, **kwargs)
        inner.add_done_callback(lambda f: self._relay(f, out))
        return out

    def _relay(self, inner: Future[Any], out: Future[Any]) -> None:
        with self._lock:
            self._pending.discard(out)
        try:
            if inner.cancelled():
                out.set_exception(
                    SchedulerError(
                        f"the Dask scheduler at {self.address} dropped a batch: the connection "
                        "to it was lost (did it stop?)"
                    )
                )
            elif (exc := inner.exception()) is not None:
                out.set_exception(_explain(exc, self.address))
            else:
                out.set_result(inner.result())
        except InvalidStateError:  # the watchdog failed it first
            pass

    def _fail(self, error: SchedulerError) -> None:
        with self._lock:
            self._error = error
            pending, self._pending = self._pending, set()
        for fut in pending:
            with suppress(InvalidStateError):
                fut.set_exception(error)

    def _watch(self) -> None:
        alone_since: float | None = None
        while not self._stop.wait(self._ping_every):
            try:
                n_workers = self.ping()
            except SchedulerError as err:
                if not self._stop.is_set():
                    self._fail(err)
                return
            now = time.monotonic()
            if n_workers > 0:
                alone_since = None
            elif alone_since is None:
                alone_since = now
            elif now - alone_since > self._worker_wait:
                self._fail(
                    SchedulerError(
                        f"the Dask scheduler at {self.address} has had no worker for "
                        f"{self._worker_wait:.0f} s"
                    )
                )
                return

    def ping(self) -> int:
        """How many workers the scheduler has; :class:`SchedulerError` if it does not answer."""
        try:
            rpc = self.client.scheduler
            if rpc is None:
                raise ConnectionError("the client is closed")
            info = self.client.sync(
                rpc.identity, n_workers=0, callback_timeout=self._ping_timeout
            )  # n_workers=0: the count only, not every worker's description
        except Exception as err:
            raise SchedulerError(
                f"the Dask scheduler at {self.address} did not answer within "
                f"{self._ping_timeout:.0f} s ({type(err).__name__}: {err})"
            ) from err
        return int(info["n_workers"])

    def wait_for_workers(self, timeout: float, say: Callable[[str], None] | None = None) -> int:
        """Block until the scheduler has a worker; how many it has. Fails after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        told = False
        while (n := self.ping()) == 0:
            if time.monotonic() > deadline:
                raise SchedulerError(
                    f"the Dask scheduler at {self.address} has no worker after {timeout:.0f} s; "
                    f"start some with `dask worker {self.address} --preload "
                    "tltrack.engine.dask_preload`"
                )
            if say and not told:
                say(f"waiting up to {timeout:.0f} s for a worker to join {self.address}")
                told = True
            self._stop.wait(1.0)
        return n

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Stop the watchdog; wait for the batches still out, or drop them (the client itself is
        closed by :func:`pool`, which opened it, and which does not wait)."""
        self._stop.set()
        drop = cancel_futures or not wait
        if drop:
            self._fail(SchedulerError("the sweep was stopped"))
        self._executor.shutdown(wait=not drop)


def _explain(exc: BaseException, address: str) -> BaseException:
    """Dask's errors about the cluster as :class:`SchedulerError`; a batch's own error as is."""
    from distributed import KilledWorker

    if isinstance(exc, KilledWorker):
        return SchedulerError(
            f"a batch killed every Dask worker that ran it (cluster {address}): {exc}"
        )
    return exc


@contextmanager
def pool(
    scheduler: str | None,
    *,
    connect_timeout: float = CONNECT_TIMEOUT_S,
    worker_wait: float = WORKER_WAIT_S,
    ping_every: float = PING_EVERY_S,
    ping_timeout: float = PING_TIMEOUT_S,
    say: Callable[[str], None] | None = None,
) -> Iterator[DaskPool | None]:
    """A :class:`DaskPool` on the scheduler at ``scheduler``, or None for the local pool.

    Fails with :class:`SchedulerError` if no scheduler answers within ``connect_timeout`` s, or if
    it has no worker within ``worker_wait`` s (``say`` hears that it is waiting).
    """
    if scheduler is None:
        yield None
        return
    from distributed import Client

    with _quiet(), _connected(Client, scheduler, connect_timeout) as client:
        ex = DaskPool(
            client,
            scheduler,
            ping_every=ping_every,
            ping_timeout=ping_timeout,
            worker_wait=worker_wait,
        )
        try:
            ex.wait_for_workers(worker_wait, say)
            yield ex
        finally:
            ex.shutdown(wait=False)


def probe(scheduler: str, timeout: float) -> None:
    """Connect to ``scheduler`` and ask who it is, within ``timeout`` s, or raise.

    Dask's own connect bounds the TCP connection but not the handshake that follows: a port
    that accepts and never speaks would hang the client forever. The probe runs on its own event
    loop in a thread, and is cancelled cleanly when its time is up. A connection reset (a port
    that Docker publishes before the scheduler behind it listens) is tried again meanwhile.
    """
    from distributed.comm import connect
    from distributed.security import Security

    args = Security().get_connection_args("client")  # tls:// takes its settings from Dask's config

    async def shake() -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while True:
            left = max(deadline - time.monotonic(), 0.1)
            try:
                # Dask's own timeout first, as its message says more (refused, unreachable, ...)
                comm = await asyncio.wait_for(connect(scheduler, timeout=left, **args), left + 2)
                try:
                    await comm.write({"op": "identity", "reply": True})
                    return dict(await asyncio.wait_for(comm.read(), left))
                finally:
                    await comm.close()
            except OSError:  # also a reset: a published port whose scheduler is still starting
                if time.monotonic() + 0.5 > deadline:
                    raise
                await asyncio.sleep(0.5)

    failure: list[BaseException] = []
    identity: list[dict[str, Any]] = []

    def run() -> None:
        try:
            identity.append(asyncio.run(shake()))
        except BaseException as err:
            failure.append(err)

    t = threading.Thread(target=run, name="tltrack-dask-probe", daemon=True)
    t.start()
    t.join(2 * timeout + 7)
    if t.is_alive():
        raise TimeoutError(f"no answer within {timeout:.0f} s")
    if failure:
        err = failure[0]
        raise (
            TimeoutError(f"no answer within {timeout:.0f} s")
            if isinstance(err, asyncio.TimeoutError)
            else err
        )
    kind = identity[0].get("type")
    if kind != "Scheduler":
        raise ValueError(f"it answers as a Dask {kind}, not a Scheduler")


@contextmanager
def _connected(client_type: type[Client], scheduler: str, timeout: float) -> Iterator[Client]:
    try:
        probe(scheduler, timeout)
        client = client_type(scheduler, timeout=timeout, set_as_default=False, name="tltrack")
    except (ValueError, TypeError) as err:  # not an address, or tls:// without TLS settings
        raise SchedulerError(
            f"cannot use {scheduler!r} as a Dask scheduler address: {err}. Addresses look like "
            "tcp://HOST:8786, or tls://HOST:8786 with Dask's TLS settings (docs/howto/dask.md)"
        ) from None
    except (OSError, TimeoutError) as err:
        raise SchedulerError(
            f"no Dask scheduler answers at {scheduler} (gave up after {timeout:.0f} s: "
            f"{err}). Start one (docs/howto/dask.md), or drop "
            f"--scheduler / {ENV} to run on the local process pool"
        ) from None
    try:
        yield client
    finally:
        try:
            client.close(timeout=5)  # not long: the scheduler may be gone
        except Exception as err:
            log.debug("closing the Dask client: %s", err)


#: Loggers that print tracebacks when a scheduler goes away; :class:`SchedulerError` says it once.
_NOISY = ("distributed.client", "distributed.core", "distributed.comm", "tornado.application")


@contextmanager
def _quiet() -> Iterator[None]:
    """Silence the client side's connection tracebacks while the pool is open."""
    loggers = [logging.getLogger(name) for name in _NOISY]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)
