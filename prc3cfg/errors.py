"""The error a person can act on: one line, no traceback.

Every user mistake and every bus fault ends up as a `UserError` (or a subclass) whose
message names the place (file:line:column, or bus/module), what is wrong and what to do.
The CLI prints it on stderr and exits non-zero; nothing else is caught there.
"""


class UserError(Exception):
    """A problem the user can fix; `str()` is the whole one-line message."""

    exit_code = 1


class Interrupted(UserError):
    """Ctrl-C or SIGTERM: the work stopped after the exchange in flight (`prc3cfg.shell.cancel`)."""

    exit_code = 130

    def __init__(self) -> None:
        super().__init__("interrupted")


class NotSent(Interrupted):
    """Stopped before a frame's first attempt left: it reached no module (a link whose cancel event
    was set, or an apply that could not keep the record that goes before the frame)."""


def interruption_within(error: BaseException) -> bool:
    """Whether `error` is an interruption Python wrapped on its way up: a signal handler's
    `Interrupted` raised while a class was being made comes out as a RuntimeError ("Error calling
    __set_name__ …") whose cause it is — still Ctrl-C, not a fault to show as a traceback."""
    seen: BaseException | None = error
    while seen is not None:
        if isinstance(seen, Interrupted | KeyboardInterrupt):
            return True
        seen = seen.__cause__
    return False
