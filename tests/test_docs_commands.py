"""Every command the user docs show in a code block (README.md, docs/**/*.md) still parses: `beliefnav ...`
and `python -m <our module> ...` lines are given to their own argparse parser, which is stopped right after
parsing (nothing runs). A synopsis (``[--opt X]``, ``A|B``, ``…``) is checked by its option names: each must
be one of that command's. Every option is checked by its exact name (argparse would take a unique prefix:
``--profile`` for a renamed ``--profiles``). Also: inline commands that wrap onto the next line, synopsis
lines continued without a backslash, a command in the middle of a diagram's line, and the ``make`` targets
the docs name with the commands of their recipes. Seconds, no processes, no network."""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import runpy
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
OURS = ("gcs_tools", "companion", "simvehicle")
COMMAND = re.compile(r"^(?:\$ )?(?:[A-Z_]+=\S+ )*(beliefnav|python3? -m) ")
SYNOPSIS = re.compile(r"\[|…|\.\.\.|<[^>]*>|\w\|\w| \| ")
NOT_SHELL = {"python", "json", "yaml", "text", "csv", "toml", "ini", "mermaid"}


def doc_commands() -> list[tuple[str, str, bool]]:
    """(file:line, command, fragment) of every command line in a fenced block (continuation lines joined
    as the shell joins them); ``fragment``: a command in the middle of a line (a diagram's
    ``SERIAL1 ◀─▶ beliefnav companion --master …``), checked by its option names only."""
    from gcs_tools.cli import COMMANDS

    inside = re.compile(rf"(?<=\s)beliefnav (?:{'|'.join(COMMANDS)}) .*--[a-z].*")
    out = []
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        for m in re.finditer(r"```(\w*)\n(.*?)```", text, re.S):
            prompted = m.group(1) == "text"  # a transcript: only its `$ ` lines are commands
            if m.group(1) in NOT_SHELL and not prompted:
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
                if prompted and not line.startswith("$ "):
                    continue
                fragment = not COMMAND.match(line)
                if fragment:
                    inner = inside.search(line)
                    if not inner:
                        continue
                    line = inner.group(0)
                # a synopsis or a diagram continued on the next lines without a backslash: `    [--opt X] …`
                while k < len(lines) and re.match(r"\s+\[?--[a-z]", lines[k]):
                    line += " " + re.sub(r"\s+#.*$", "", lines[k]).strip()
                    k += 1
                if line.startswith("python") and not line.split()[2].startswith(OURS):
                    continue  # not ours (python3 -m venv, pip)
                out.append((f"{doc.relative_to(ROOT)}:{first + start}", line, fragment))
    return out


def inline_commands() -> list[tuple[str, str]]:
    """(file:line, command) of every inline code span outside fenced blocks that starts like a command:
    often a fragment (``beliefnav sitl --vehicle``), so only its option names are checked. A command
    named without ``beliefnav`` but with an option (``replay --coupling tight``, ``gnss spp --systems GE``)
    counts as one."""
    from gcs_tools.cli import COMMANDS

    bare = re.compile(rf"(?:{'|'.join(COMMANDS)})(?: [a-z][\w-]*)? --[a-z]")
    out = []
    for doc in DOCS:
        text = re.sub(r"```.*?```", lambda m: "\n" * m.group(0).count("\n"), doc.read_text(encoding="utf-8"),
                      flags=re.S)
        # a span may wrap onto the next line (not across a paragraph)
        for m in re.finditer(r"(?<!`)`((?:[^`\n]|\n(?!\s*\n))+)`(?!`)", text):
            span = " ".join(m.group(1).split())
            if bare.match(span):
                span = f"beliefnav {span}"
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
def _stop_after_parsing(seen: list[argparse.ArgumentParser]):
    """argparse's top-level parse returns into an exception: the command is parsed, never run. Every
    parser that parses (the command's, its subcommands') is appended to ``seen``."""
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
        seen.append(self)
        top(parse_args, self, args, namespace)

    def stop_known(self, args=None, namespace=None):
        seen.append(self)
        if depth[0]:
            return parse_known(self, args, namespace)  # a subparser, or inside parse_args
        top(parse_known, self, args, namespace)

    # undone on leaving (not at the test's end): each command parses against argparse's own methods,
    # not through the wrappers of every command parsed before it
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(argparse.ArgumentParser, "parse_args", stop_args)
        patch.setattr(argparse.ArgumentParser, "parse_known_args", stop_known)
        yield


def parse(words: list[str], monkeypatch: pytest.MonkeyPatch,
          options: dict[str, str | None] | None = None) -> tuple[str | None, str]:
    """(None when ``words`` parse, else the parser's error; what it printed to stdout). ``options`` gets
    the exact option strings of the parsers that parsed (hidden ones too), each mapped to None, or for a
    deprecated spelling (``gcs_tools.choices.add_deprecated_alias``) to its new name."""
    from gcs_tools.cli import main

    err, out = io.StringIO(), io.StringIO()
    seen: list[argparse.ArgumentParser] = []
    try:
        with _stop_after_parsing(seen), contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
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
    finally:
        if options is not None:
            options.update((o, getattr(action, "new", None)) for parser in seen
                           for o, action in parser._option_string_actions.items())


def check(line: str, monkeypatch: pytest.MonkeyPatch, names_only: bool = False) -> str | None:
    """None when the documented command is fine, else what is wrong with it."""
    known: dict[str, str | None] = {}
    if not SYNOPSIS.search(line) and not names_only:
        words = argv_of(line)
        error = parse(words, monkeypatch, known)[0]
        if error:
            return error
        named = [w.split("=")[0] for w in words if w.startswith("--")]
        head = words[:2]
    else:
        # a synopsis: each option it names is one of the command's (its words up to the first option,
        # placeholders and all, then --help)
        words = argv_of(re.sub(r"<[^>]*>", "X", line).replace("[", " ").replace("]", " "))
        head = []
        for w in words:
            if w.startswith("-") and w != "-m":
                break
            if not re.fullmatch(r"[A-Z_]+|…|\.\.\.", w):  # a placeholder (NAME, LOG, …) is not a subcommand
                head.append(w)
        error = parse([*head, "--help"], monkeypatch, known)[0]
        if error:
            return f"{' '.join(head)} --help: {error}"
        named = re.findall(r"(?<![\w-])--[a-z0-9][a-z0-9-]*", line)
    # by its exact name: argparse also takes a unique prefix, so a renamed `--profiles` would still
    # accept the docs' stale `--profile`; and not by an old spelling kept working for scripts
    unknown = [o for o in named if o not in known]
    old = [f"{o} is now {known[o]}" for o in named if known.get(o)]
    if unknown:
        return f"not an option of {' '.join(head)}: {', '.join(unknown)}"
    return f"renamed: {', '.join(old)}" if old else None


# runpy warns that a module it runs as __main__ was imported before (by an earlier command): harmless here
RUNPY_WARNING = "ignore:.*found in sys.modules after import of package:RuntimeWarning"


@pytest.mark.filterwarnings(RUNPY_WARNING)
def test_every_documented_command_parses(monkeypatch: pytest.MonkeyPatch) -> None:
    commands = doc_commands()
    assert len(commands) > 60  # the docs are full of them: the collector finds them
    bad = [f"{where}: {line}\n    {problem}" for where, line, fragment in commands
           if (problem := check(line, monkeypatch, names_only=fragment)) is not None]
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
    "beliefnav replay tests/data/quad106.tlog --no-fig",  # argparse takes the prefix of --no-figures
    "beliefnav replay LOG [--no-fig]",
    "python -m gcs_tools.evaluate.nlos_probe --missions 0-3",  # a deprecated spelling: works, with a note
    "beliefnav evaluate --missions 3 --seeds 0",
])
def test_the_check_finds_a_stale_command(line: str, monkeypatch: pytest.MonkeyPatch) -> None:
    assert check(line, monkeypatch) is not None


def test_a_command_kept_working_under_a_hidden_option_is_fine(monkeypatch: pytest.MonkeyPatch) -> None:
    # sitl's --drop-probability is hidden from --help (loss injection for tests) but is an option
    assert check("beliefnav sitl --mission test --seed 0 --drop-probability 0.1", monkeypatch) is None
    fragment = "beliefnav sitl --mission test --seed S --drop-probability 0.1"
    assert check(fragment, monkeypatch, names_only=True) is None


def test_the_collector_finds_wrapped_and_continued_commands(tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    doc = tmp_path / "doc.md"
    doc.write_text("Run `beliefnav replay LOG\n--no-fig` to see, or `gnss spp --sys GE`.\n\n"
                   "```\nbeliefnav gnss spp INPUT [--nav NAV]\n    [--no-such-option]\n"
                   "SERIAL1 <-> beliefnav companion --master tcp:HOST:PORT --feed F\n"
                   "    --no-such-feed X\n```\n",
                   encoding="utf-8")
    monkeypatch.setattr(sys.modules[__name__], "DOCS", [doc])
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert inline_commands() == [("doc.md:1", "beliefnav replay LOG --no-fig"),
                                 ("doc.md:2", "beliefnav gnss spp --sys GE")]
    assert all(check(span, monkeypatch, names_only=True) for _, span in inline_commands())
    assert doc_commands() == [
        ("doc.md:5", "beliefnav gnss spp INPUT [--nav NAV] [--no-such-option]", False),
        ("doc.md:7", "beliefnav companion --master tcp:HOST:PORT --feed F --no-such-feed X", True)]


def test_the_collector_joins_continuations_as_the_shell_does() -> None:
    assert argv_of("$ A_B=1 beliefnav fly --out x  # comment") == ["beliefnav", "fly", "--out", "x"]
    assert argv_of("python -m gcs_tools.evaluate.real --flights reporting | tee log") == [
        "-m", "gcs_tools.evaluate.real", "--flights", "reporting"]


@pytest.mark.filterwarnings(RUNPY_WARNING)
def test_the_examples_in_beliefnav_help_parse(monkeypatch: pytest.MonkeyPatch) -> None:
    error, text = parse(["beliefnav", "--help"], monkeypatch)
    assert error is None, error
    examples = [re.split(r"\s{2,}", x.strip())[0] for x in text.splitlines() if x.startswith("  beliefnav ")]
    assert len(examples) >= 5
    bad = [f"beliefnav --help: {line}\n    {problem}" for line in examples
           if (problem := check(line, monkeypatch)) is not None]
    assert not bad, "\n".join(bad)


def make_targets() -> set[str]:
    """The targets the docs name: `make NAME` in a code span or at the start of a fenced line."""
    names = set()
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        names.update(re.findall(r"(?:`|^)make ([a-z][\w-]*)", text, re.M))
    return names


@pytest.mark.skipif(shutil.which("make") is None, reason="no make")
@pytest.mark.filterwarnings(RUNPY_WARNING)
def test_every_documented_make_target_exists_and_its_commands_parse(monkeypatch: pytest.MonkeyPatch) -> None:
    targets = sorted(make_targets())
    assert {"demo", "test", "bench", "results", "results-ablation"} <= set(targets)
    # -n: print the recipes, run nothing; -B: every recipe, as on a fresh clone
    env = {k: v for k, v in os.environ.items() if not k.startswith("MAKE")}
    done = subprocess.run(["make", "-n", "-B", *targets], cwd=ROOT, capture_output=True, text=True,
                          timeout=60, env=env)
    assert done.returncode == 0, done.stderr  # a target the docs name that the Makefile lacks fails here
    lines = re.sub(r"\\\n\s*", " ", done.stdout).splitlines()  # the shell's continuation lines joined
    ours = re.compile(r"^\S*/bin/(?=beliefnav |python3? -m (?:gcs_tools|companion|simvehicle)\b)")
    commands = [ours.sub("", x) for x in lines if ours.match(x)]
    assert len(commands) >= 15  # demo, bench, results, the ablation's and paramdoc's
    bad = [f"Makefile: {line}\n    {problem}" for line in commands
           if (problem := check(line, monkeypatch)) is not None]
    assert not bad, "\n".join(bad)


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
