"""Every command the user docs show in a code block (README.md, docs/**/*.md) still parses: `beliefnav ...`
and `python -m <our module> ...` lines are given to their own argparse parser, which is stopped right after
parsing (nothing runs). A synopsis (``[--opt X]``, ``A|B``, ``…``) is checked by its option names: each must
be in that command's ``--help``. Seconds, no processes, no network."""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import runpy
import shlex
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
OURS = ("gcs_tools", "companion", "simvehicle")
COMMAND = re.compile(r"^(?:\$ )?(?:[A-Z_]+=\S+ )*(beliefnav|python3? -m) ")
SYNOPSIS = re.compile(r"\[|…|\.\.\.|<[^>]*>|\w\|\w| \| ")
NOT_SHELL = {"python", "json", "yaml", "text", "csv", "toml", "ini", "mermaid"}


def doc_commands() -> list[tuple[str, str]]:
    """(file:line, command) of every command line in a fenced block (continuation lines joined as the
    shell joins them)."""
    out = []
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        for m in re.finditer(r"```(\w*)\n(.*?)```", text, re.S):
            if m.group(1) in NOT_SHELL:
                continue
            first = text[: m.start()].count("\n") + 2
            lines = m.group(2).split("\n")
            k = 0
            while k < len(lines):
                line, start = lines[k], k
                while line.endswith("\\") and k + 1 < len(lines):
                    k += 1
                    line = line[:-1] + lines[k]
                k += 1
                line = re.sub(r"\s+#.*$", "", line).strip()  # a trailing shell comment
                if COMMAND.match(line):
                    if line.startswith("python") and not line.split()[2].startswith(OURS):
                        continue  # not ours (python3 -m venv, pip)
                    out.append((f"{doc.relative_to(ROOT)}:{first + start}", line))
    return out


def inline_commands() -> list[tuple[str, str]]:
    """(file:line, command) of every inline code span outside fenced blocks that starts like a command:
    often a fragment (``beliefnav sitl --vehicle``), so only its option names are checked."""
    out = []
    for doc in DOCS:
        text = re.sub(r"```.*?```", lambda m: "\n" * m.group(0).count("\n"), doc.read_text(encoding="utf-8"),
                      flags=re.S)
        for m in re.finditer(r"`([^`\n]+)`", text):
            span = m.group(1).strip()
            ours = COMMAND.match(span) and (not span.startswith("python") or span.split()[2].startswith(OURS))
            if ours:
                out.append((f"{doc.relative_to(ROOT)}:{text[: m.start()].count(chr(10)) + 1}", span))
    return out


def argv_of(line: str) -> list[str]:
    """The command's words: up to a shell operator or comment, without a ``$ `` prompt or env settings."""
    lex = shlex.shlex(line.removeprefix("$ "), posix=True, punctuation_chars="|&;<>")
    lex.whitespace_split = True
    lex.commenters = "#"
    words = []
    for w in lex:
        if set(w) <= set("|&;<>"):
            break
        words.append(w)
    while words and re.match(r"^[A-Z_]+=", words[0]):
        words.pop(0)
    if words[0].startswith("python"):
        words = words[1:]  # -m MODULE ...
    return words


class _ParsedError(Exception):
    pass


@contextlib.contextmanager
def _stop_after_parsing():
    """argparse's top-level parse returns into an exception: the command is parsed, never run."""
    parse_args, parse_known = argparse.ArgumentParser.parse_args, argparse.ArgumentParser.parse_known_args
    depth = [0]

    def top(parse, self, args, namespace):
        depth[0] += 1
        try:
            got = parse(self, args, namespace)
        finally:
            depth[0] -= 1
        raise _ParsedError(got)

    def stop_args(self, args=None, namespace=None):
        top(parse_args, self, args, namespace)

    def stop_known(self, args=None, namespace=None):
        if depth[0]:
            return parse_known(self, args, namespace)  # a subparser, or inside parse_args
        top(parse_known, self, args, namespace)

    # undone on leaving (not at the test's end): each command parses against argparse's own methods,
    # not through the wrappers of every command parsed before it
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(argparse.ArgumentParser, "parse_args", stop_args)
        patch.setattr(argparse.ArgumentParser, "parse_known_args", stop_known)
        yield


def parse(words: list[str], monkeypatch: pytest.MonkeyPatch) -> tuple[str | None, str]:
    """(None when ``words`` parse, else the parser's error; what it printed to stdout)."""
    from gcs_tools.cli import main

    err, out = io.StringIO(), io.StringIO()
    with _stop_after_parsing(), contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            if words[0] == "beliefnav":
                main(words[1:])
            else:
                assert words[0] == "-m", words
                monkeypatch.setattr(sys, "argv", [words[1], *words[2:]])
                runpy.run_module(words[1], run_name="__main__", alter_sys=True)
        except _ParsedError:
            return None, out.getvalue()
        except SystemExit as exc:
            if exc.code in (0, None):  # --help
                return None, out.getvalue()
            return f"exit {exc.code}: {err.getvalue().strip()}", out.getvalue()
    return "returned without parsing its arguments", out.getvalue()


def check(line: str, monkeypatch: pytest.MonkeyPatch, names_only: bool = False) -> str | None:
    """None when the documented command is fine, else what is wrong with it."""
    if not SYNOPSIS.search(line) and not names_only:
        return parse(argv_of(line), monkeypatch)[0]
    # a synopsis: each option it names is one of the command's (its words up to the first option,
    # placeholders and all, then --help)
    words = argv_of(re.sub(r"<[^>]*>", "X", line).replace("[", " ").replace("]", " "))
    head = []
    for w in words:
        if w.startswith("-") and w != "-m":
            break
        if not re.fullmatch(r"[A-Z_]+|…|\.\.\.", w):  # a placeholder (NAME, LOG, …) is not a subcommand
            head.append(w)
    error, text = parse([*head, "--help"], monkeypatch)
    if error:
        return f"{' '.join(head)} --help: {error}"
    known = set(re.findall(r"--[a-z0-9][a-z0-9-]*", text))
    unknown = [o for o in re.findall(r"(?<![\w-])--[a-z0-9][a-z0-9-]*", line) if o not in known]
    return f"not an option of {' '.join(head)}: {', '.join(unknown)}" if unknown else None


# runpy warns that a module it runs as __main__ was imported before (by an earlier command): harmless here
RUNPY_WARNING = "ignore:.*found in sys.modules after import of package:RuntimeWarning"


@pytest.mark.filterwarnings(RUNPY_WARNING)
def test_every_documented_command_parses(monkeypatch: pytest.MonkeyPatch) -> None:
    commands = doc_commands()
    assert len(commands) > 60  # the docs are full of them: the collector finds them
    bad = [f"{where}: {line}\n    {problem}" for where, line in commands
           if (problem := check(line, monkeypatch)) is not None]
    assert not bad, "\n".join(bad)


@pytest.mark.filterwarnings(RUNPY_WARNING)
def test_every_option_named_in_an_inline_command_exists(monkeypatch: pytest.MonkeyPatch) -> None:
    spans = inline_commands()
    assert len(spans) > 100
    bad = [f"{where}: {span}\n    {problem}" for where, span in spans
           if (problem := check(span, monkeypatch, names_only=True)) is not None]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("line", [
    "beliefnav replay tests/data/quad106.tlog --no-such-option",
    "beliefnav replay tests/data/quad106.tlog --method",  # an option without its value
    "python -m gcs_tools.evaluate.real --no-such-option",
    "beliefnav replay LOG [--no-such-option] --out DIR",  # a synopsis naming an option that is not there
])
def test_the_check_finds_a_stale_command(line: str, monkeypatch: pytest.MonkeyPatch) -> None:
    assert check(line, monkeypatch) is not None


def test_the_collector_joins_continuations_as_the_shell_does() -> None:
    assert argv_of("$ A_B=1 beliefnav fly --out x  # comment") == ["beliefnav", "fly", "--out", "x"]
    assert argv_of("python -m gcs_tools.evaluate.real --flights reporting | tee log") == [
        "-m", "gcs_tools.evaluate.real", "--flights", "reporting"]


MAIN_COMMANDS = ["beliefnav", "beliefnav replay", "beliefnav gnss spp", "beliefnav bench"]


@pytest.mark.parametrize("command", MAIN_COMMANDS)
def test_every_option_of_a_main_command_is_in_the_docs(command: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The converse: what ``--help`` offers for the commands a new user tries first is named somewhere in
    README.md or docs/ (gnss spp's --no-earth-rotation and --elevation-mask-deg were not)."""
    error, text = parse([*command.split(), "--help"], monkeypatch)
    assert error is None, error
    options = set(re.findall(r"(?<![\w-])--[a-z0-9][a-z0-9-]*", text)) - {"--help"}
    assert options
    docs = "\n".join(doc.read_text(encoding="utf-8") for doc in DOCS)
    missing = sorted(o for o in options if not re.search(re.escape(o) + r"(?![\w-])", docs))
    assert not missing, f"{command}: in --help but in no doc: {', '.join(missing)}"
