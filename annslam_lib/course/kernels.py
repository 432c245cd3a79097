"""Running a notebook top to bottom on a fresh kernel, without a silent stall.

The course's own tools run notebooks with nbclient (``./course.sh refresh``, the student-run
and release tests, ``benchmarks/stall_experiment.py``). Plain nbclient can sit idle for a
whole cell time-out and then carry on as if nothing happened, and it does so under load:

- nbclient mimics a front end for ipywidgets' ``Output`` widget (every ``interact``): when the
  kernel prints into one, nbclient sends the widget's new state back on the *shell* channel,
  while it is waiting on that same channel for the cell's ``execute_reply``;
- jupyter_client's ``Session.send`` sends through a synchronous shadow of the asyncio socket,
  behind pyzmq's back. libzmq's notification descriptor (``ZMQ_FD``) is edge-triggered and a
  send processes the socket's pending commands: if the reply arrived in that instant, the
  send consumes its notification, and the asyncio poll waiting for the reply is never woken;
- at the poll's time-out pyzmq checks the socket once more, finds the reply, and nbclient
  goes on without an error. Measured here: cells of 0.1 s CPU that took exactly their 120 s
  (or 30 s) time-out, 1 in 6 runs of chapter 00 with two busy processes beside it.

:class:`CourseKernelClient` fixes it where it happens: after every send on one of its
channels it reads the socket's ``EVENTS`` through the asyncio socket, which pyzmq documents
as re-arming its pending polls. And it makes any stall of this kind loud: an
``execute_reply`` that reaches it more than :data:`LATE_S` seconds after the kernel sent it
raises :class:`KernelStallError` instead of being taken as on time.
:class:`CourseNotebookClient` is nbclient's client with it; any other Jupyter tool that
starts kernels with jupyter_client's ``AsyncKernelManager`` (nbconvert, nbgrader's
autograde) can use it through its configuration::

    c.AsyncKernelManager.client_class = "annslam_lib.course.kernels.CourseKernelClient"
"""
from __future__ import annotations

import datetime as _dt
import time
from pathlib import Path

import zmq
from jupyter_client.asynchronous import AsyncKernelClient
from jupyter_client.channels import AsyncZMQSocketChannel
from nbclient import NotebookClient
from traitlets import Type

__all__ = ["CourseKernelClient", "CourseNotebookClient", "RearmingChannel", "ShellChannel",
           "KernelStallError", "check_on_time", "run_notebook", "LATE_S"]

LATE_S = 10.0      # an execute_reply this late was sitting unseen in the client's socket


class KernelStallError(RuntimeError):
    """A reply sat unseen in the client's socket: the client stalled, not the kernel."""


class RearmingChannel(AsyncZMQSocketChannel):
    """An asyncio channel whose sends cannot hide a message that has just arrived."""

    def send(self, msg) -> None:
        super().send(msg)           # jupyter_client sends through a synchronous shadow socket
        try:
            self.socket.get(zmq.EVENTS)     # pyzmq re-arms its pending polls on EVENTS
        except zmq.ZMQError:                # a closed socket: nothing waits on it
            pass


class ShellChannel(RearmingChannel):
    """The shell channel, which also refuses to take a late ``execute_reply`` as on time."""

    late_s = LATE_S

    async def get_msg(self, timeout=None):
        msg = await super().get_msg(timeout)
        check_on_time(msg, self.late_s)
        return msg


def check_on_time(msg: dict, late_s: float) -> None:
    """Raise :class:`KernelStallError` if ``msg`` is an ``execute_reply`` the kernel sent
    more than ``late_s`` seconds ago (other replies, e.g. the start-up handshake's spare
    ``kernel_info_reply``, may legitimately wait in the socket)."""
    sent = msg.get("header", {}).get("date")
    if msg.get("msg_type") != "execute_reply" or not isinstance(sent, _dt.datetime):
        return
    if sent.tzinfo is None:
        sent = sent.replace(tzinfo=_dt.timezone.utc)
    late = (_dt.datetime.now(_dt.timezone.utc) - sent).total_seconds()
    if late > late_s:
        raise KernelStallError(
            f"the kernel answered {late:.0f} s before the client saw it: the client stalled "
            "on a lost notification of its shell socket (annslam_lib.course.kernels explains)")


class CourseKernelClient(AsyncKernelClient):
    """jupyter_client's asyncio kernel client with :class:`RearmingChannel` channels and a
    shell channel that raises :class:`KernelStallError` on a late reply."""

    shell_channel_class = Type(ShellChannel)
    iopub_channel_class = Type(RearmingChannel)
    stdin_channel_class = Type(RearmingChannel)
    control_channel_class = Type(RearmingChannel)


class CourseNotebookClient(NotebookClient):
    """nbclient's ``NotebookClient`` talking to its kernel through :class:`CourseKernelClient`."""

    def create_kernel_manager(self):
        km = super().create_kernel_manager()
        km.client_class = f"{__name__}.CourseKernelClient"
        return km


def run_notebook(nb, cwd, *, timeout: float = 300, allow_errors: bool = False,
                 kernel_name: str = "python3", **traits) -> float:
    """Execute ``nb`` (an nbformat notebook, changed in place) top to bottom on a fresh
    kernel started in ``cwd``, each cell within ``timeout`` seconds; returns the seconds."""
    t0 = time.perf_counter()
    CourseNotebookClient(nb, timeout=timeout, kernel_name=kernel_name,
                         allow_errors=allow_errors, record_timing=False,
                         resources={"metadata": {"path": str(Path(cwd))}}, **traits).execute()
    return time.perf_counter() - t0
