"""Types of the command line's numeric and address options (argparse ``type=``).

Each refuses a bad value while the command line is parsed, before anything is read, started or
simulated: argparse then prints one line naming the option, what it takes and the value given
(``isaac replay: error: argument --tolerance: must be a finite number >= 0, got 'inf'``) and
exits with status 2 (`isaac.app.cli.Parser`). Numbers are always finite: ``nan``, ``inf`` and
text that overflows a float (``1e400``) are refused; whole numbers are written as integers
(``1e3`` is refused) and bounded above where a bigger value would never finish.
"""

from __future__ import annotations

import argparse
import ipaddress
import math
from collections.abc import Callable

MAX_PORT = 65535


def _text(x: float) -> str:
    """A bound as a person writes it: an int in full (100000000), a float shortest (0.5)."""
    return str(x) if isinstance(x, int) else f"{x:g}"


def _bounds(minimum, maximum, *, above: bool = False) -> str:
    """The bounds in words: ">= 0", "> 0", ">= 1 and <= 1000"."""
    low = f"> {_text(minimum)}" if above else f">= {_text(minimum)}"
    return low if maximum is None else f"{low} and <= {_text(maximum)}"


def integer(*, minimum: int, maximum: int | None = None) -> Callable[[str], int]:
    """A whole number in [minimum, maximum] (no maximum when None)."""
    wanted = f"must be a whole number {_bounds(minimum, maximum)}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:  # not an integer, or more digits than Python converts
            raise argparse.ArgumentTypeError(f"{wanted}, got {text!r}") from None
        if value < minimum or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"{wanted}, got {text!r}")
        return value

    return parse


def number(
    *, minimum: float, above: bool = False, maximum: float | None = None
) -> Callable[[str], float]:
    """A finite float >= minimum (> minimum when ``above``), <= maximum when given."""
    wanted = f"must be a finite number {_bounds(minimum, maximum, above=above)}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{wanted}, got {text!r}") from None
        low_ok = value > minimum if above else value >= minimum
        if not (math.isfinite(value) and low_ok and (maximum is None or value <= maximum)):
            raise argparse.ArgumentTypeError(f"{wanted}, got {text!r}")
        return value

    return parse


def port(text: str) -> int:
    """A TCP port, 0 to 65535 (0: a free one, chosen at start)."""
    return integer(minimum=0, maximum=MAX_PORT)(text)


def ip_address(text: str) -> str:
    """An IPv4 or IPv6 address to listen on, as its canonical text; ``localhost`` is
    127.0.0.1 (the name alone: other host names are refused, a server binds an address)."""
    if text.strip().lower() == "localhost":
        return "127.0.0.1"
    try:
        return str(ipaddress.ip_address(text.strip()))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be an IP address (127.0.0.1: this machine only; 0.0.0.0 or :: for every "
            f"interface), got {text!r}"
        ) from None


def server_address(text: str) -> str:
    """A server's address as Dask writes it, ``[SCHEME://]HOST:PORT`` (tcp://10.0.0.5:8786,
    tls://scheduler.lan:8786, 127.0.0.1:8786; an IPv6 host in brackets), PORT 1 to 65535.
    Whether the server answers is found when it is called, not here."""
    wanted = "must be [tcp://]HOST:PORT, PORT 1-65535"
    rest = text.split("://", 1)[1] if "://" in text else text
    host, colon, digits = rest.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not (colon and host and digits.isdigit()) or any(c in host for c in "/ []"):
        raise argparse.ArgumentTypeError(f"{wanted}, got {text!r}")
    if not 1 <= int(digits) <= MAX_PORT:
        raise argparse.ArgumentTypeError(f"{wanted}, got {text!r}")
    return text


def url_host(address: str) -> str:
    """``address`` as the host of a URL: an IPv6 address in brackets, its zone's ``%`` as
    ``%25`` (RFC 3986, RFC 6874)."""
    return f"[{address.replace('%', '%25')}]" if ":" in address else address
