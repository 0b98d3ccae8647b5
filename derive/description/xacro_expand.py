"""xacro -> URDF text, before the URDF reader (``derive import-urdf robot.urdf.xacro``).

URDF = expand(xacro file, args, package folders), with the ``xacro`` package from PyPI (the optional
extra ``derive-robotics[xacro]``) and no ROS: the ROS lookups xacro would make are answered from the
folders given here.

- A file is xacro when its name ends in ``.xacro`` or it uses xacro (an element in the xacro
  namespace, a ``${...}`` or ``$(...)`` substitution; :func:`is_xacro`); anything else is read as
  plain URDF, untouched.
- ``args`` are xacro's ``NAME:=VALUE`` arguments (``--arg NAME=VALUE``); one that the file
  neither declares nor reads is named in a warning (a misspelling would otherwise pass silently).
- ``packages`` maps a ROS package name to its folder (``--package-path NAME=DIR``): ``$(find NAME)``
  gives DIR, and an include or ``xacro.load_yaml`` of ``package://NAME/REST``
  reads DIR/REST. A package not given falls back to xacro's own lookup (ament, where ROS is
  installed) and otherwise is one line naming the option. ``$(dirname)`` is the folder of the file
  being expanded.
- Every file xacro opens for an include goes through derive's guards
  (:func:`derive.description.files.read_bytes`: a regular file, at most 16 MiB, UTF-8), and the
  expanded text is held to the same 16 MiB.
- Any xacro error (an undefined arg, an unknown package, a bad macro, malformed XML) is one line
  naming the file, the included file and the macro it came from; a missing ``xacro`` package is one
  line naming the extra to install.

The hooks are set on xacro's module functions for the expansion only and restored after it;
nothing in site-packages changes. xacro keeps its state in module globals, so expansions run one at
a time (as derive's commands do).
"""

from __future__ import annotations

import contextlib
import os
import re
import shlex
import stat
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping

from derive.description.files import MAX_FILE_BYTES, InputFileError, read_bytes
from derive.errors import DeriveError

EXTRA = "pip install 'derive-robotics[xacro]'"
XACRO_NAMESPACES = ("http://www.ros.org/wiki/xacro", "http://ros.org/wiki/xacro", "http://wiki.ros.org/xacro")
_XACRO_ELEMENT = re.compile(rb"<xacro:")
_SUBSTITUTION = re.compile(r"\$[{(]")
_PACKAGE_URL = re.compile(r"^package://([^/]+)/?(.*)$")


class XacroError(DeriveError):
    """A xacro file that cannot be expanded; the message names the file."""


def is_xacro(path: str | Path, data: bytes) -> bool:
    """Whether ``path`` (with contents ``data``) is a xacro file: a ``.xacro`` name, or xacro in use.

    In use means an element in the xacro namespace, an attribute with a ``${...}`` or ``$(...)``
    substitution, or a ``<xacro:`` element whose prefix is not declared. A declaration alone is not
    use: many published URDFs (example-robot-data's ur5) are xacro output that kept ``xmlns:xacro``,
    and they read as plain URDF, with or without the xacro package.
    """
    if str(path).endswith(".xacro"):
        return True
    if b"xacro" not in data:
        return False
    try:
        root = ET.fromstring(data)
    except ET.ParseError:
        return _XACRO_ELEMENT.search(data) is not None  # an undeclared prefix: xacro itself reads it
    except (RecursionError, MemoryError):
        return False  # the URDF reader says what is wrong
    for el in root.iter():
        if isinstance(el.tag, str) and el.tag.startswith("{") and el.tag[1:].partition("}")[0] in XACRO_NAMESPACES:
            return True
        if any(_SUBSTITUTION.search(v) for v in el.attrib.values()):
            return True
    return False


def assignments(items: Mapping[str, Any] | Iterable[str] | None, option: str, what: str) -> dict[str, str]:
    """``["a=1", "b=x"]`` (or ``{"a": 1}``) -> ``{"a": "1", "b": "x"}``; XacroError on a malformed item.

    ``option`` names the command-line option in messages (``--arg``), ``what`` the value (``VALUE``).
    """
    if items is None:
        return {}
    if isinstance(items, Mapping):
        pairs = [(str(k), str(v)) for k, v in items.items()]
    else:
        pairs = []
        for item in items:
            name, eq, value = str(item).partition("=")
            if not eq or not name.strip():
                raise XacroError(f"{option} {item!r}: expected NAME={what}")
            pairs.append((name.strip(), value))
    out: dict[str, str] = {}
    for name, value in pairs:
        if not re.fullmatch(r"[A-Za-z0-9_.\-]+", name):
            raise XacroError(f"{option} {name!r}: a name is letters, digits, '_', '.' and '-'")
        if name in out and out[name] != value:
            raise XacroError(f"{option} {name}: given twice ({out[name]!r} and {value!r})")
        out[name] = value
    return out


def package_folders(items: Mapping[str, Any] | Iterable[str] | None) -> dict[str, Path]:
    """``--package-path NAME=DIR`` items -> {NAME: DIR}; XacroError if a DIR is not a folder."""
    out = {}
    for name, folder in assignments(items, "--package-path", "DIR").items():
        path = Path(folder)
        if not path.is_dir():
            raise XacroError(f"--package-path {name}={folder}: not a folder")
        out[name] = path
    return out


class _Args(dict):
    """xacro's arg table that remembers which names the file asked for (declared with ``<xacro:arg>``
    or read with ``$(arg)``), so that an ``--arg`` nobody asked for can be named."""

    def __init__(self, given: Mapping[str, str]):
        super().__init__(given)
        self.asked: set[str] = set()

    def __contains__(self, key: object) -> bool:
        self.asked.add(str(key))
        return super().__contains__(key)

    def __getitem__(self, key: str) -> str:
        self.asked.add(str(key))
        return super().__getitem__(key)


class _Context(dict):
    """xacro's substitution context, with ``filename`` the file being expanded (for ``$(dirname)``)."""

    def __init__(self, filestack: Any):
        super().__init__()
        self.filestack = filestack

    def get(self, key: str, default: Any = None) -> Any:
        if key == "filename":
            stack = self.filestack()
            return stack[-1] if stack else default
        return super().get(key, default)

    def __getitem__(self, key: str) -> Any:
        if key == "filename":
            return self.get(key)
        return super().__getitem__(key)


@contextlib.contextmanager
def _hooks(xacro: Any, shown: str, packages: Mapping[str, Path]) -> Iterator[None]:
    """Answer xacro's ROS lookups from ``packages`` and read its files through derive's guards, then restore."""
    from xacro import substitution_args as sa

    ros_find = sa._eval_find
    ros_parse = xacro.parse
    ros_abs = xacro.abs_filename_spec
    ros_context = xacro.substitution_args_context

    def find(pkg: str) -> str:
        if pkg in packages:  # absolute: xacro reads a relative include path from the including file's folder
            return os.path.abspath(packages[pkg])
        try:
            return ros_find(pkg)
        except Exception:  # no ament (ImportError), or it does not know the package
            raise XacroError(f"{shown}: xacro: $(find {pkg}): unknown package '{pkg}': give its folder with "
                             f"--package-path {pkg}=DIR") from None

    def abs_filename(spec: str) -> str:
        url = _PACKAGE_URL.match(spec)
        if url:
            spec = os.path.join(find(url.group(1)), url.group(2))
        path = ros_abs(spec)
        with contextlib.suppress(OSError):  # a missing file: xacro says so when it opens it
            if not stat.S_ISREG(os.stat(path).st_mode) and not re.search("[*[?]", path):
                raise XacroError(f"{shown}: xacro: {path}: cannot read it: not a regular file")
        return path

    def parse(inp: Any, filename: str | None = None) -> Any:
        if inp is None:  # an include: through the guards (regular file, size, UTF-8)
            try:
                data = read_bytes(os.path.join(xacro.root_dir, filename), "xacro include")
                inp = data.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise XacroError(f"{shown}: xacro: {filename}: not UTF-8 text (byte {exc.start})") from None
            except InputFileError as exc:
                raise XacroError(f"{shown}: xacro: {exc}") from None
        return ros_parse(inp, filename)

    def warning(*args: Any, **_: Any) -> None:  # one line naming the file, as derive's own warnings
        print(_one_line(f"warning: {shown}: xacro: {' '.join(map(str, args))}"), file=sys.stderr)

    ros_warning, ros_location = xacro.warning, xacro.print_location
    sa._eval_find = find
    sa._eval_dict["find"] = find  # find() inside $(eval ...), the same answer
    xacro.parse = parse
    xacro.abs_filename_spec = abs_filename
    xacro.substitution_args_context = _Context(lambda: xacro.filestack)
    xacro.warning = warning
    xacro.print_location = lambda: None  # its "when processing file:" lines: the warning names the file
    try:
        yield
    finally:
        sa._eval_find = ros_find
        sa._eval_dict["find"] = ros_find
        xacro.parse = ros_parse
        xacro.abs_filename_spec = ros_abs
        xacro.substitution_args_context = ros_context
        xacro.warning, xacro.print_location = ros_warning, ros_location


def _one_line(text: str) -> str:
    return "; ".join(part.strip() for part in str(text).splitlines() if part.strip())


def _problem(exc: BaseException) -> str:
    """xacro's message of ``exc``, one line, with the way forward where there is one."""
    from xacro.substitution_args import ArgException

    inner: Any = exc
    for _ in range(20):  # xacro wraps what it catches in XacroException(exc=...), at times twice
        if isinstance(inner, ArgException):
            return f"undefined substitution argument '{inner}': give it with --arg {inner}=VALUE"
        inner = getattr(inner, "exc", None)
    if isinstance(exc, RecursionError):
        return "macros or properties nest too deeply (one that expands to itself?)"
    text = _one_line(str(exc)) or type(exc).__name__
    return text


def _cause(exc: BaseException | None) -> XacroError | None:
    """Our own error, if xacro wrapped one (it re-raises what substitution args raise as its own)."""
    seen = 0
    while exc is not None and seen < 20:
        if isinstance(exc, XacroError):
            return exc
        exc = getattr(exc, "exc", None) or exc.__cause__ or exc.__context__
        seen += 1
    return None


def expand(path: str | Path, data: bytes, shown: str, args: Mapping[str, str] | None = None,
           packages: Mapping[str, Path] | None = None) -> bytes:
    """The URDF that the xacro file ``path`` (read already: ``data``; ``shown`` in messages) expands to."""
    try:
        import xacro
    except ImportError:
        raise XacroError(f"{shown}: this file is xacro; install the extra: {EXTRA}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise XacroError(f"{shown}: xacro is not UTF-8 text (byte {exc.start})") from None
    given = _Args(args or {})
    top = str(path)
    with _hooks(xacro, shown, packages or {}):
        xacro.init_stacks(top)
        xacro.all_includes = []
        try:
            doc = xacro.parse(text, top)
            xacro.process_doc(doc, mappings=given)
            out = doc.toxml(encoding="utf-8")
        except XacroError:
            raise
        except Exception as exc:  # xacro raises XacroException, ExpatError, NameError, ... (it has no base)
            own = _cause(exc)
            if own is not None:
                raise own from None
            where = []
            stack = [f for f in (xacro.filestack or []) if f]
            if stack and stack[-1] != top:
                where.append(f"in {stack[-1]}")
            macros = [m.body.getAttribute("name") for m in (xacro.macrostack or []) if getattr(m, "body", None)]
            if macros:
                where.append(f"in macro '{macros[-1]}'")
            raise XacroError(f"{shown}: xacro: {_problem(exc)}" + (f" ({', '.join(where)})" if where else "")) from None
        finally:
            xacro.init_stacks(None)
    if len(out) > MAX_FILE_BYTES:
        raise XacroError(f"{shown}: xacro expands to more than {MAX_FILE_BYTES // 2**20} MiB")
    unused = sorted(set(given) - given.asked)
    if unused:
        print(f"warning: {shown}: --arg {', '.join(unused)}: the xacro file declares no such arg (ignored)",
              file=sys.stderr)
    return out


def command_options(args: Mapping[str, str], packages: Mapping[str, Any]) -> str:
    """`` --arg NAME=VALUE ... --package-path NAME=DIR ...`` for the import command (shell-quoted)."""
    return "".join(f" --arg {shlex.quote(f'{k}={v}')}" for k, v in args.items()) + "".join(
        f" --package-path {shlex.quote(f'{k}={v}')}" for k, v in packages.items())
