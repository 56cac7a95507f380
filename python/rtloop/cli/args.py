"""What the three commands share on their command lines: the argument types (each error says what was
expected), the parser that reports instead of exiting, the help texts for boards and responses, and
the runner of a command with subcommands."""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from ..errors import RtloopError

__all__ = ["BOARD_HELP", "RESPONSE_HELP", "Parser", "UsageError", "choice", "flag", "float_in", "formatter",
           "generations", "info", "int_at_least", "length", "nonneg_int", "positive_float", "positive_int",
           "run_subcommands", "size", "triple"]

BOARD_HELP = (
    "the ChArUco board: a JSON file written by 'rtloop-acquire board', or COLSxROWS,SQUARE,MARKER[,DICT] "
    "with lengths in metres or with mm/cm (e.g. 7x5,40mm,30mm,DICT_5X5_100: 7 squares across, 5 down, "
    "40 mm squares, 30 mm markers). Measure the printed square: printers scale."
)
RESPONSE_HELP = (
    "how the photo's stored values relate to light: srgb (default: camera JPEG/PNG), linear (raw sensor "
    "data, e.g. a 16-bit TIFF from dcraw -4 -T), gamma:G (linear = value^G), or a table file (CSV "
    'CODE,LINEAR or CODE,R,G,B per line, or JSON {"codes": [...], "linear": [...]})'
)


class UsageError(Exception):
    """A problem with the command line found by argparse (exit status 2); ``prog`` names the (sub)command."""

    def __init__(self, message: str, prog: str):
        super().__init__(message)
        self.prog = prog


class Parser(argparse.ArgumentParser):
    """An ArgumentParser that raises UsageError instead of printing and exiting."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(message, self.prog)


def choice(parser: Any, flag: str, choices: tuple[str, ...], help: str, **more: Any) -> None:
    """The option ``flag`` taking one of ``choices``, the first its default."""
    parser.add_argument(flag, choices=choices, default=choices[0], help=help, **more)


def flag(parser: Any, name: str, help: str) -> None:
    """The on/off option ``name``: off unless given."""
    parser.add_argument(name, action="store_true", help=help)


def formatter(parser_class: Any = argparse.RawDescriptionHelpFormatter) -> Callable[[str], Any]:
    return lambda prog: parser_class(prog, max_help_position=32, width=100)


def int_at_least(minimum: int, what: str, not_a_number: str | None = None) -> Callable[[str], int]:
    """A whole number >= ``minimum``; ``what`` (and ``not_a_number`` for text that is no number) is said."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {not_a_number or what}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
        return value

    return parse


def int_in(lo: int, hi: int) -> Callable[[str], int]:
    """A whole number in [lo, hi]."""
    what = f"a whole number from {lo} to {hi}"
    at_least = int_at_least(lo, what)

    def parse(text: str) -> int:
        value = at_least(text)
        if value > hi:
            raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
        return value

    return parse


def norm(text: str) -> str:
    """A loss norm: auto (chosen from the photo), l1, l2, huber or huber:H with H > 0 (checked here, before
    the fit)."""
    if text in ("auto", "l1", "l2", "huber"):
        return text
    if text.startswith("huber:"):
        try:
            h = float(text[len("huber:"):])
        except ValueError:
            h = math.nan
        if math.isfinite(h) and h > 0:
            return text
    raise argparse.ArgumentTypeError(f"expected auto, l1, l2, huber or huber:H with H > 0, got {text!r}")


def float_in(lo: float, hi: float, lo_open: bool, what: str, not_a_number: str | None = None
             ) -> Callable[[str], float]:
    """A finite number in [lo, hi] (or (lo, hi] with ``lo_open``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {not_a_number or what}, got {text!r}") from None
        if not (math.isfinite(value) and (value > lo if lo_open else value >= lo) and value <= hi):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text}")
        return value

    return parse


def generations(text: str) -> int | tuple[int, int]:
    """N or N1,N2: generations of both stages, or of the light and the colour stages."""
    parts = [p.strip() for p in text.split(",")]
    try:
        values = [int(p) for p in parts]
    except ValueError:
        values = []
    if len(values) not in (1, 2) or min(values) < 0:
        raise argparse.ArgumentTypeError(
            f"expected N or N1,N2 (whole numbers >= 0: light stages, colour stages), got {text!r}"
        )
    return values[0] if len(values) == 1 else (values[0], values[1])


def length(text: str) -> float:
    """A length > 0 in metres, or with a unit: 0.0335, 33.5mm, 3.35cm."""
    try:
        from ..acquisition.boards import length_m  # here: boards imports OpenCV

        v = length_m(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a length such as 0.0335, 33.5mm or 3.35cm, got {text!r}"
        ) from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a length > 0, got {text!r}")
    return v


def length_or_zero(text: str) -> float:
    """A length of 0 or more in metres, or with a unit: 0, 0.5mm, 0.05cm."""
    try:
        from ..acquisition.boards import length_m  # here: boards imports OpenCV

        v = length_m(text)
    except ValueError:
        v = float("nan")
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(
            f"expected a length of 0 or more such as 0, 0.0005 or 0.5mm, got {text!r}")
    return v


def triple(text: str) -> tuple[float, float, float]:
    """X,Y,R in pixels (a circle)."""
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"expected X,Y,R in pixels, got {text!r}")
    return vals  # type: ignore[return-value]


def size(text: str) -> tuple[int, int]:
    """WIDTHxHEIGHT in pixels."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 1920x1080, got {text!r}") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"expected a positive size, got {text!r}")
    return w, h


def run_subcommands(build: Callable[[], Parser], argv: Sequence[str] | None, prog: str) -> int:
    """Parse ``argv`` and run the chosen subcommand's handler; the exit status (2: bad command line, 1:
    bad input or failed step, 130: interrupted)."""
    parser = build()
    try:
        args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    except UsageError as exc:
        print(f"{exc.prog}: error: {exc}", file=sys.stderr)
        print(f"run '{prog} --help' for the options", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    if getattr(args, "handler", None) is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # e.g. enlarging a small photo: reported otherwise
            return int(args.handler(args) or 0)
    except (RtloopError, ValueError) as exc:
        message = " ".join(str(exc).split())
        print(f"{prog}: error: {message}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130


#: Argument types of the acquisition commands.
positive_int = int_at_least(1, "a whole number >= 1", "a whole number")
nonneg_int = int_at_least(0, "a whole number >= 0", "a whole number")
positive_float = float_in(0.0, math.inf, True, "a number > 0", "a number")


def info(text: str) -> None:
    """A line for the user on stderr (stdout is for results)."""
    print(text, file=sys.stderr)


def vignetting(text: str) -> str | tuple[float, float]:
    """--vignetting: auto, on, off or K1,K2 (two finite numbers)."""
    if text in ("auto", "on", "off"):
        return text
    parts = text.split(",")
    try:
        k = tuple(float(v) for v in parts)
    except ValueError:
        k = ()
    if len(k) != 2 or not all(math.isfinite(v) for v in k):
        raise argparse.ArgumentTypeError(f"{text!r}: 'auto', 'on', 'off' or K1,K2 (two numbers)")
    return (k[0], k[1])
