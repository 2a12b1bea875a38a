"""`buddybot people enrol|list|forget`: the table and the request checks (pure),
then the verb as a process against a real router and a small stand-in for the
identity service's three queryables (what is tested here is the command's
output and exit codes, not the identity service)."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable

import pytest

from buddybot import cli
from buddybot.cli.people import NOT_RUNNING, request, table_lines
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import UsageError
from buddybot.runtime.node import Node
from buddybot.tools.testing import buddybot_argv, retry_until

S = 1_000_000_000
T0 = 1_700_000_000 * S


def test_the_table_lists_everybody_by_name_with_the_retention_rule() -> None:
    known = m.KnownPeople(people=[
        m.KnownPerson(name="grace", enrolled_ns=T0, last_seen_ns=None, samples=5),
        m.KnownPerson(name="Ada", enrolled_ns=T0, last_seen_ns=T0 + 86400 * S, samples=3)],
        retention_days=30)
    lines = table_lines(known)
    assert lines[0].split() == ["NAME", "ENROLLED", "LAST", "SEEN", "SAMPLES"]
    assert lines[1].startswith("Ada ") and lines[1].endswith("3")
    assert lines[2].startswith("grace") and "never" in lines[2]
    assert lines[3] == "forgotten after 30 days unseen"
    assert table_lines(m.KnownPeople()) == [
        "nobody enrolled", "kept until forgotten (no retention limit)"]


def test_a_request_outside_the_contract_is_a_usage_error_naming_the_field() -> None:
    """The check itself is the SDK's (tests/sdk/test_identity.py); here its exit status."""
    with pytest.raises(UsageError, match=r"^samples: "):
        request(m.EnrolRequest, name="Ada", samples=0)


class FakeIdentity:
    """The identity service's queryables with a gallery of names only."""

    def __init__(self, node: Node) -> None:
        self.people: dict[str, m.KnownPerson] = {}
        self.requests: list[object] = []
        node.serve(keys.IDENTITY_ENROL, self.enrol)
        node.serve(keys.IDENTITY_FORGET, self.forget)
        node.serve(keys.IDENTITY_LIST, self.list)

    def enrol(self, req: m.EnrolRequest) -> m.EnrolReply:
        self.requests.append(req)
        if req.name == "Nobody":
            return m.EnrolReply(success=False, message="no face in front of the camera")
        if req.name in self.people and not req.replace:
            return m.EnrolReply(success=False, message=f"{req.name} is already enrolled")
        self.people[req.name] = m.KnownPerson(name=req.name, enrolled_ns=m.now_ns(),
                                              samples=req.samples)
        return m.EnrolReply(success=True, name=req.name, samples=req.samples)

    def forget(self, req: m.ForgetRequest) -> m.ForgetReply:
        self.requests.append(req)
        if req.all:
            gone = sorted(self.people)
            self.people.clear()
            return m.ForgetReply(success=True, forgotten=gone)
        if req.name not in self.people:
            return m.ForgetReply(success=False, message=f"nobody called {req.name}")
        del self.people[req.name]
        return m.ForgetReply(success=True, forgotten=[str(req.name)])

    def list(self, _req: m.Trigger) -> m.KnownPeople:
        return m.KnownPeople(people=list(self.people.values()))


def people_cli(endpoint: str, *args: str, stdin: str | None = None
               ) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("people", *args, "--connect", endpoint),
                          capture_output=True, text=True, timeout=60, input=stdin)


@pytest.mark.integration
def test_without_an_identity_service_every_verb_says_how_to_start_one(endpoint: str) -> None:
    for args in (("list", "--timeout", "1"), ("forget", "Ada", "--timeout", "1")):
        got = people_cli(endpoint, *args)
        assert got.returncode == 1, got.stderr
        assert NOT_RUNNING in got.stderr


@pytest.mark.integration
def test_enrol_list_forget_from_the_command_line(
        node_factory: Callable[..., Node], endpoint: str, probe: Node) -> None:
    identity = FakeIdentity(node_factory("identity"))
    retry_until(lambda: any(keys.IDENTITY_LIST.key() in i.services
                            for i in probe.node_infos(1.0)), 30, 0.2, "identity queryables")

    enrolled = people_cli(endpoint, "enrol", " Ada ", "--samples", "3", "--timeout", "4")
    assert enrolled.returncode == 0, enrolled.stderr
    assert enrolled.stdout.strip() == "enrolled Ada (3 samples)"
    asked = identity.requests[-1]
    assert isinstance(asked, m.EnrolRequest)
    assert (asked.name, asked.samples, asked.timeout_s) == ("Ada", 3, 4.0)
    assert asked.sent_ns > 0  # so a later forget wins over it
    again = people_cli(endpoint, "enrol", "Ada")
    assert again.returncode == 1 and "already enrolled" in again.stdout
    assert people_cli(endpoint, "enrol", "Ada", "--replace").returncode == 0
    no_face = people_cli(endpoint, "enrol", "Nobody", "--json")
    assert no_face.returncode == 1 and json.loads(no_face.stdout)["success"] is False
    assert people_cli(endpoint, "enrol", "Grace").returncode == 0

    listed = people_cli(endpoint, "list")
    assert listed.returncode == 0, listed.stderr
    assert [line.split()[0] for line in listed.stdout.splitlines()[1:3]] == ["Ada", "Grace"]
    data = json.loads(people_cli(endpoint, "list", "--json").stdout)
    assert sorted(p["name"] for p in data["people"]) == ["Ada", "Grace"]

    forgot = people_cli(endpoint, "forget", "Ada")
    assert forgot.returncode == 0 and forgot.stdout.strip() == "forgot Ada"
    unknown = people_cli(endpoint, "forget", "Ada")
    assert unknown.returncode == 1 and "nobody called Ada" in unknown.stdout
    # --all asks first: no terminal and no --yes is a usage error; a "no" refuses.
    asked = people_cli(endpoint, "forget", "--all", stdin="")
    assert asked.returncode == 2 and "--yes" in asked.stderr
    assert "Grace" in identity.people
    everybody = people_cli(endpoint, "forget", "--all", "--yes")
    assert everybody.returncode == 0 and everybody.stdout.strip() == "forgot Grace"
    assert identity.people == {}


@pytest.mark.parametrize("args", [
    ("forget",), ("forget", "Ada", "--all", "--yes"), ("forget", "Ada", "--yes"),
    ("enrol",), ("enrol", ""), ("enrol", "x" * 10_000), ("enrol", "Ada", "--samples", "0"),
    ("enrol", "Ada", "--timeout", "600")])
def test_bad_usage_exits_2_before_asking_anyone(args: tuple[str, ...],
                                               capsys: pytest.CaptureFixture[str]) -> None:
    try:
        status = cli.main(["people", *args, "--connect", "tcp/127.0.0.1:9"])
    except SystemExit as exc:  # argparse's own usage errors
        status = exc.code  # type: ignore[assignment]
    err = capsys.readouterr().err
    assert status == 2, err
    assert "router" not in err


class _Terminal:
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize(("answer", "status"), [("n", 1), ("", 1)])
def test_forget_all_asks_on_a_terminal_and_a_no_forgets_nobody(
        answer: str, status: int, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr("sys.stdin", _Terminal())
    asked: list[str] = []
    monkeypatch.setattr("builtins.input", lambda prompt: asked.append(prompt) or answer)
    # Nothing is asked of any router: the refusal comes first.
    assert cli.main(["people", "forget", "--all", "--connect", "tcp/127.0.0.1:9"]) == status
    assert asked == ["forget every enrolled person? [y/N] "]
    assert "nothing forgotten" in capsys.readouterr().err
