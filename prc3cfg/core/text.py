"""Text from files is data: what a name may hold, and how text from a plant or plan file is shown.

Owns the characters that are not printable text (`CONTROL`: C0, DEL, C1, the line and
paragraph separators U+2028/2029 and lone surrogates) and one escaping per medium that prc3cfg
prints such text in:

- `plain` — a terminal or a log: each such character as Python's repr writes it (`\\x1b`,
  `\\n`, `\\u2028`, `\\ud800`), without the quotes, so that nothing from a file moves the cursor,
  rings, sets a colour, starts a line of its own or cannot be encoded;
- `shown` — text another user wrote (their records in the machine's folder), for a terminal: as
  `plain`, and the bidirectional formatting characters (`BIDI`) too, so that none can reorder
  what is printed after it;
- `github_data`, `github_property` — a GitHub workflow command (`::error file=…::message`):
  `%`, CR and LF as `%25`, `%0D`, `%0A`, and in a property `:` and `,` too (docs.github.com,
  "Workflow commands for GitHub Actions"), so that nothing from a file starts a command line;
- `markdown` — a pull-request comment's paragraph or table cell: markdown's and HTML's
  metacharacters as entities, an `@` followed by a zero-width joiner and the `:` of a URL and the
  `.` of `www.` as entities, so that no text from a file makes a mention, a link, an image,
  emphasis, a table cell or HTML; `markdown_html` — the same inside HTML (`<summary>`), where
  markdown is not read: `<`, `>`, `&` as entities, `@` and URLs broken alike.

Names in a plant file are refused when they hold a `CONTROL` character (`prc3cfg.plant.models`);
a plan file is data that anyone may have edited, so everything shown of it goes through these.
Pure.
"""

from __future__ import annotations

import html
import re

#: What is not printable text: C0 and DEL, C1, U+2028 LINE SEPARATOR, U+2029 PARAGRAPH SEPARATOR
#: (a new line to JavaScript and to some terminals), and lone surrogates (no encoding can write them).
CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff]")


#: The bidirectional formatting characters: embeddings and overrides U+202A–202E, isolates
#: U+2066–2069, the marks U+200E/200F and U+061C — each can reorder the rest of a terminal's line.
BIDI = re.compile("[\u202a-\u202e\u2066-\u2069\u200e\u200f\u061c]")
_SHOWN = re.compile(f"{CONTROL.pattern}|{BIDI.pattern}")


def has_control(text: str) -> bool:
    """Whether `text` holds a character that is not printable text (`CONTROL`)."""
    return CONTROL.search(text) is not None


def _escaped(match: re.Match[str]) -> str:
    return repr(match.group())[1:-1]


def plain(text: str) -> str:
    """`text` for a terminal or a log: every `CONTROL` character as repr escapes it, "m1\\x1b[2J" → "m1\\\\x1b[2J"."""
    return CONTROL.sub(_escaped, text) if CONTROL.search(text) else text


def shown(text: str) -> str:
    """`text` for a terminal, whoever wrote it: every `CONTROL` and `BIDI` character as repr escapes it
    ("\\x1b", "\\u202e"), the rest as written."""
    return _SHOWN.sub(_escaped, text) if _SHOWN.search(text) else text


def github_data(text: str) -> str:
    """`text` as the message of a GitHub workflow command: `%`, CR, LF escaped; other control characters as `plain`."""
    return plain(text.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A"))


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
    text = plain(text)
    text = "".join(_MARKDOWN.get(c, c) for c in text) if any(c in _MARKDOWN for c in text) else text
    return _LIVE.sub(_dead, text)


def markdown_html(text: str) -> str:
    """`text` inside HTML in a markdown comment (`<summary>…</summary>`): shown as written, nothing in it live."""
    return _LIVE.sub(_dead, html.escape(plain(text), quote=False))


def _dead(match: re.Match[str]) -> str:
    """What GitHub would make live, made text: "@" with a zero-width joiner after it, ":" or "." as an entity."""
    return "@\u200d" if match.group() == "@" else f"&#{ord(match.group())};"
