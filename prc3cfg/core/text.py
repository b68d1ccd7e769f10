"""Text from files is data: what a name may hold, and how text from a plant or plan file is shown.

Owns the characters that are not printable text (`UNPRINTABLE`: the Unicode general categories
of control characters — C0, DEL, C1 —, format characters — bidirectional overrides, isolates and
marks, zero-width spaces and joiners, the byte order mark, soft hyphens, tags —, the line and
paragraph separators U+2028/2029 and lone surrogates) and one escaping per medium that prc3cfg
prints such text in:

- `shown` — a terminal or a log: each such character as Python's repr writes it (`\\x1b`,
  `\\n`, `\\u202e`, `\\u2028`, `\\ud800`), without the quotes, so that nothing from a file moves
  the cursor, rings, sets a colour, starts a line of its own, reorders or hides what a reader
  sees, or cannot be encoded;
- `github_data`, `github_property` — a GitHub workflow command (`::error file=…::message`):
  `%`, CR and LF as `%25`, `%0D`, `%0A`, and in a property `:` and `,` too (docs.github.com,
  "Workflow commands for GitHub Actions"), so that nothing from a file starts a command line;
- `markdown` — a pull-request comment's paragraph or table cell: markdown's and HTML's
  metacharacters as entities, an `@` followed by an empty HTML comment and the `:` of a URL and the
  `.` of `www.` as entities, so that no text from a file makes a mention, a link, an image,
  emphasis, a table cell or HTML; `markdown_html` — the same inside HTML (`<summary>`), where
  markdown is not read: `<`, `>`, `&` as entities, `@` and URLs broken alike.

Names in a plant file are refused when they hold an `UNPRINTABLE` character (`prc3cfg.plant.models`);
a plan file is data that anyone may have edited, so everything shown of it goes through these.
Also how a set of module addresses is said, in every output and refusal (`address_ranges`). Pure.
"""

from __future__ import annotations

import re
import unicodedata
from collections.abc import Iterable

#: What is not printable text, by Unicode general category: Cc (C0, DEL, C1), Cf (format: the
#: bidirectional overrides U+202A–202E, isolates U+2066–2069 and marks U+200E/200F/061C that
#: reorder what is shown, zero-width spaces and joiners, U+FEFF, soft hyphens, tags, which hide
#: text), Cs (lone surrogates: no encoding can write them), Zl and Zp (U+2028/2029: a new line to
#: JavaScript and to some terminals). The categories, not a list, so that a newer Python's Unicode
#: database adds the format characters it knows.
UNPRINTABLE = frozenset({"Cc", "Cf", "Cs", "Zl", "Zp"})


def _unprintable(c: str) -> bool:
    return unicodedata.category(c) in UNPRINTABLE


def has_control(text: str) -> bool:
    """Whether `text` holds a character that is not printable text (`UNPRINTABLE`)."""
    # isprintable is False for every such character
    return not text.isprintable() and any(map(_unprintable, text))


def shown(text: str) -> str:
    """`text` for a terminal or a log: every `UNPRINTABLE` character as repr escapes it, "m1\\x1b[2J" →
    "m1\\\\x1b[2J"."""
    if text.isprintable():
        return text
    return "".join(repr(c)[1:-1] if _unprintable(c) else c for c in text)


def github_data(text: str) -> str:
    """`text` as the message of a GitHub workflow command: `%`, CR, LF escaped; other unprintable characters
    as `shown`."""
    return shown(text.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A"))


def github_property(text: str) -> str:
    """`text` as a property of a GitHub workflow command (`file=…`): as `github_data`, and `:` and `,` too."""
    return github_data(text).replace(":", "%3A").replace(",", "%2C")


#: Markdown's and HTML's metacharacters, as entities: they mean the character in a paragraph, a
#: table cell and HTML alike (a backslash escape would show as typed inside HTML). Parentheses and
#: quotes stay as written: without `[`, `]` and `!` they make no link or image, and outside a tag no HTML.
_MARKDOWN = {c: f"&#{ord(c)};" for c in "\\`*_[]!|~#<>&"}
#: What GitHub would make live from plain text: a mention or team (`@name`), an autolinked URL
#: (`https://…`, `www.…`) or e-mail address.
_LIVE = re.compile(r"@|:(?=//)|(?<=www)\.", re.IGNORECASE)


def markdown(text: str) -> str:
    """`text` for a markdown paragraph or table cell: shown as written, with nothing live in it."""
    text = shown(text)
    text = "".join(_MARKDOWN.get(c, c) for c in text) if any(c in _MARKDOWN for c in text) else text
    return _LIVE.sub(_dead, text)


def markdown_html(text: str) -> str:
    """`text` inside HTML in a markdown comment (`<summary>…</summary>`): shown as written, nothing in it
    live."""
    import html  # here: every command's start-up (`--help` too) imports this module for `shown`

    return _LIVE.sub(_dead, html.escape(shown(text), quote=False))


def _dead(match: re.Match[str]) -> str:
    """What GitHub would make live, made text: "@" with an empty HTML comment after it (rendered as nothing,
    and copied from the page as nothing — a zero-width joiner came along into every paste), ":" or "." as an
    entity."""
    return "@<!-- -->" if match.group() == "@" else f"&#{ord(match.group())};"


def _runs(numbers: Iterable[int]) -> list[list[int]]:
    """`numbers`, sorted, cut where one is not the one before plus one."""
    runs: list[list[int]] = []
    for n in sorted(numbers):
        if runs and n == runs[-1][-1] + 1:
            runs[-1].append(n)
        else:
            runs.append([n])
    return runs


def number_runs(numbers: Iterable[int]) -> str:
    """"1–8, 13": program numbers as runs."""
    return ", ".join(f"{run[0]}–{run[-1]}" if len(run) > 1 else str(run[0]) for run in _runs(numbers))


def address_ranges(addresses: Iterable[int]) -> str:
    """"address 5", "addresses 7–30", "addresses 2, 4–6" (a run of two as two)."""
    runs = _runs(addresses)
    text = ", ".join(f"{r[0]}–{r[-1]}" if len(r) > 2 else ", ".join(map(str, r)) for r in runs)
    return f"address{'es' if sum(map(len, runs)) > 1 else ''} {text}"
