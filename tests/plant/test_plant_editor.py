"""The schema in the editor plant engineers use: Red Hat's yaml-language-server (VS Code's YAML
extension, and most editors' YAML support), spoken to over the Language Server Protocol.

Completion inserts a value prc3cfg takes (a factory default or an example, never a bare 0
below a minimum), and a program number out of 1..64 is marked where it is written, though
YAML keeps it an integer. `.ci/run` installs the server (`npm install -g yaml-language-server`);
without it these tests are skipped.
"""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest
from tools import needs, which

from prc3cfg.plant import PlantError
from prc3cfg.shell.plant_files import load_plant

SCHEMA = Path(__file__).parents[2] / "schemas" / "plant.schema.json"
SERVER = which("yaml-language-server")
pytestmark = needs("yaml-language-server")

PLANT = f"""\
# yaml-language-server: $schema={SCHEMA}
plant: editor
profiles:
  booth:
    system:
      max_speed: 0.500
{" " * 6}
    programs:
      1:
        position: 0.300
{" " * 8}
      0: {{position: 0.200, speed: 0.100}}
      64: {{position: 0.200, speed: 0.100}}
      65: {{position: 0.200, speed: 0.100}}
buses:
  - name: line
    port: emulator://line
    modules:
      - {{address: 1, name: m1, profiles: booth}}
"""
SYSTEM_LINE, PROGRAM_LINE = 6, 10  # the blank lines inside `system:` and program 1, indented as a key there


class Server:
    """yaml-language-server on stdio: JSON-RPC messages with Content-Length headers."""

    def __init__(self, root: Path) -> None:
        self.process = subprocess.Popen([SERVER, "--stdio"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=subprocess.DEVNULL)
        self.last_id = 0
        self.notifications: list[dict] = []
        capabilities = {"textDocument": {"completion": {"completionItem": {"snippetSupport": True}}}}
        self.request("initialize",
                     {"processId": None, "rootUri": root.as_uri(), "capabilities": capabilities})
        self.notify("initialized", {})
        self.notify("workspace/didChangeConfiguration",
                    {"settings": {"yaml": {"validate": True, "completion": True,
                                           "schemaStore": {"enable": False}}}})

    def send(self, message: dict) -> None:
        body = json.dumps({"jsonrpc": "2.0", **message}).encode()
        self.process.stdin.write(b"Content-Length: %d\r\n\r\n%s" % (len(body), body))
        self.process.stdin.flush()

    def receive(self) -> dict:
        length = None
        while (line := self.process.stdout.readline()) not in (b"\r\n", b""):
            name, _, value = line.decode().partition(":")
            length = int(value) if name.lower() == "content-length" else length
        assert length is not None, "yaml-language-server closed its output"
        message = json.loads(self.process.stdout.read(length))
        if "method" in message and "id" in message:  # the server asks: settings, or anything else
            settings = [{"validate": True, "completion": True}] * len(message["params"].get("items", []))
            self.send({"id": message["id"], "result": settings
                       if message["method"] == "workspace/configuration" else None})
        return message

    def request(self, method: str, params: dict) -> object:
        self.last_id += 1
        self.send({"id": self.last_id, "method": method, "params": params})
        while (message := self.receive()).get("id") != self.last_id or "method" in message:
            self.notifications.append(message)
        assert "error" not in message, message
        return message["result"]

    def notify(self, method: str, params: dict) -> None:
        self.send({"method": method, "params": params})

    def diagnostics(self, uri: str) -> list[dict]:
        while True:
            for message in self.notifications:
                if (message.get("method") == "textDocument/publishDiagnostics"
                    and message["params"]["uri"] == uri):
                    return message["params"]["diagnostics"]
            self.notifications.append(self.receive())

    def close(self) -> None:
        self.request("shutdown", None)
        self.notify("exit", None)
        self.process.stdin.close()
        assert self.process.wait() == 0
        self.process.stdout.close()


@pytest.fixture(scope="module")
def opened(tmp_path_factory):
    """The plant open in the editor: (server, its URI, its lines)."""
    path = tmp_path_factory.mktemp("editor") / "plant.yaml"
    path.write_text(PLANT)
    server = Server(path.parent)
    uri = path.as_uri()
    server.notify("textDocument/didOpen",
                  {"textDocument": {"uri": uri, "languageId": "yaml", "version": 1, "text": PLANT}})
    yield server, uri
    server.close()


def completions(server: Server, uri: str, line: int, column: int) -> dict[str, str]:
    """What completing at line:column would insert, by key, placeholders filled with their text."""
    found = server.request("textDocument/completion",
                           {"textDocument": {"uri": uri}, "position": {"line": line, "character": column}})
    items = found["items"] if isinstance(found, dict) else found
    inserted = {i["label"]: i.get("insertText") or i["textEdit"]["newText"] for i in items}
    return {label: re.sub(r"\$\{\d+:([^}]*)\}|\$\d+", r"\1", text) for label, text in inserted.items()}


def written(tmp_path: Path, line: int, text: str, speed: str = "speed: 0.100") -> Path:
    """The plant with `text` at `line` (program 1's speed at its blank line, unless that is
    `line`), without programs 0 and 65 (their test is below)."""
    lines = PLANT.splitlines()
    for blank, added in {PROGRAM_LINE: speed, line: text}.items():
        lines[blank] += added
    path = tmp_path / "plant.yaml"
    path.write_text("\n".join(line for line in lines if not re.match(r"\s+(0|65):", line)) + "\n")
    return path


def test_completing_a_system_parameter_inserts_its_factory_default(opened, tmp_path):
    server, uri = opened
    inserted = completions(server, uri, SYSTEM_LINE, 6)
    assert inserted["min_speed"] == "min_speed: 0.01" and inserted["alarm"] == "alarm: false"
    assert "max_speed" not in inserted  # already written
    for text in inserted.values():  # each one, written into the plant, is taken as it is
        load_plant(written(tmp_path, SYSTEM_LINE, text))


def test_completing_a_program_field_inserts_a_value_prc3cfg_takes(opened, tmp_path):
    server, uri = opened
    inserted = completions(server, uri, PROGRAM_LINE, 8)
    assert inserted["speed"] == "speed: 0.05" and inserted["dwell"] == "dwell: 0"
    plant = load_plant(written(tmp_path, PROGRAM_LINE, inserted["speed"]))
    assert plant.buses[0].modules[0].desired_programs()[1].V == 50


def test_a_program_number_out_of_range_is_marked_where_it_is_written(opened, tmp_path):
    server, uri = opened
    marked = {d["range"]["start"]["line"]: d["message"] for d in server.diagnostics(uri)
              if d["severity"] == 1}
    numbers = {i: line.split(":")[0].strip() for i, line in enumerate(PLANT.splitlines())}
    assert {numbers[line] for line in marked} == {"0", "65"}, marked
    (tmp_path / "plant.yaml").write_text(PLANT)
    with pytest.raises(PlantError) as refused:  # prc3cfg says the same of the same lines
        load_plant(tmp_path / "plant.yaml")
    problems = str(refused.value).splitlines()
    assert sorted(int(line.split(":")[1]) - 1 for line in problems
                  if "out of range" in line) == sorted(marked)
    # checked beside them: one pass
    assert [line.split(": ", 1)[1] for line in problems if "out of range" not in line] == [
        "in module m1, program 1 has no speed — give speed: in the module or in one of its profiles"]
