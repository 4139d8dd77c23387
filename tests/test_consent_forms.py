"""A new version of the consent form, a consent held on paper, and the consent odds and ends (trial33 A, D, H, J).

Before: `[study] consent_form` lived only in the study file, fixed with the folder, so "recorded again for a new
version of the form" (README, docs/study.md) could not happen; consent was always "given now", so a consent
held on paper for an older folder was journaled after the games it covered; a step refused for lack of consent
showed as [open]; `--consent-withdrawn` was journaled for someone who never consented; `serve --pilot p01=a,p01=b`
took one silently; and `protocol repair` of a torn ConsentGiven left participants.csv claiming the consent.
"""

from __future__ import annotations

import csv
import io
import json
import zipfile

from pairplay.errors import command_word
from pairplay.replay.studydata import StudyData
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.server import ConsoleServer
from pairplay.services.protocol import StudyRunner

from test_consent import journal, study_with_form, table
from test_console_api import call


def one_line(r) -> str:
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r
    return r.stderr


def made_earlier(folder) -> None:
    """The study folder as if made on 2026-11-01 (its StudyCreated's time): a consent signed on paper before the
    test ran is after it, as in a study under way (a time before the folder was made is refused)."""
    path = folder / "journal.jsonl"
    lines = path.read_text().splitlines(keepends=True)
    created = json.loads(lines[0])
    assert created["event"] == "StudyCreated"
    created["time_ns"] = 1793491200 * 10**9
    path.write_text(json.dumps(created, separators=(",", ":")) + "\n" + "".join(lines[1:]))


def test_a_new_consent_form_is_journaled_and_people_consent_to_it_again(tmp_path, pairplay_cli):
    folder = tmp_path / "st a;b"  # a folder a shell splits: every suggested command quotes it
    assert pairplay_cli("protocol", "init", folder, "--study", study_with_form(tmp_path, "v1")).returncode == 0
    assert pairplay_cli("protocol", "register", folder, "--count", "2", "--consent").returncode == 0
    study_file = (folder / "study.toml").read_bytes()
    r = pairplay_cli("protocol", "consent-form", folder, "v2 2026-12")  # the ethics board approved v2
    assert r.returncode == 0 and "consent form from now on: 'v2 2026-12'" in r.stdout, r
    assert "p01, p02: their next game waits" in r.stdout
    assert f"`pairplay protocol consent {command_word(folder)} ID`" in r.stdout and "st a;b' ID`" in r.stdout
    assert (folder / "study.toml").read_bytes() == study_file  # the study file stays as it was made
    assert [e["form"] for e in journal(folder) if e["event"] == "ConsentFormChanged"] == ["v2 2026-12"]
    assert "is 'v2 2026-12' already" in one_line(pairplay_cli("protocol", "consent-form", folder, "v2 2026-12"))
    assert "must be one line" in one_line(pairplay_cli("protocol", "consent-form", folder, "v3\n"))
    # who signed only v1 waits: said by status, and a person's game is refused
    status = pairplay_cli("protocol", "status", folder).stdout
    assert "p01: consent to 'v1' only, the study's consent form is now 'v2 2026-12'" in status, status
    assert "[waits  ] p01: phase1 game 1  (waits for consent: consent to 'v1' only" in status, status
    data = StudyData(folder)
    for pid in ("p01", "p02"):
        try:
            data.check_consent(pid)
            raise AssertionError(f"{pid} plays on a consent to v1 only")
        except Exception as err:
            assert "consent to 'v1' only" in str(err) and "'v2 2026-12'" in str(err), err
    r = pairplay_cli("protocol", "consent", folder, "p01")  # to the study's form now, by default
    assert r.returncode == 0 and "consent recorded: form 'v2 2026-12' given " in r.stdout, r
    StudyData(folder).check_consent("p01")
    rows = table(folder / "participants.csv")
    assert [(r["participant"], r["consent_form"]) for r in rows] == [("p01", "v2 2026-12"), ("p02", "v1")]
    assert "recorded already" in one_line(pairplay_cli("protocol", "consent", folder, "p01"))
    # a consent to an earlier form, recorded now (on paper): journaled, said as not enough
    r = pairplay_cli("protocol", "register", folder)
    r = pairplay_cli("protocol", "consent", folder, "p03", "--form", "v1")
    assert r.returncode == 0 and "form 'v1'" in r.stdout and "p03 has consent to 'v1' only" in r.stderr, r


def test_a_consent_held_on_paper_is_journaled_as_given_then_and_recorded_now(tmp_path, pairplay_cli):
    folder = tmp_path / "study"
    assert pairplay_cli("protocol", "init", folder, "--study", study_with_form(tmp_path)).returncode == 0
    assert pairplay_cli("protocol", "register", folder, "--count", "2").returncode == 0
    made_earlier(folder)
    r = pairplay_cli("protocol", "consent", folder, "p01", "--given-at", "2026-11-20T10:00Z")
    assert r.returncode == 0, r
    assert r.stdout.startswith("p01: consent recorded: form 'v2 2026-11' given 2026-11-20T10:00:00Z (recorded 20"), r
    [given] = [e for e in journal(folder) if e["event"] == "ConsentGiven"]
    assert given["given_ns"] == 1795168800 * 10**9 and given["time_ns"] > given["given_ns"]
    [row] = [r for r in table(folder / "participants.csv") if r["participant"] == "p01"]
    assert row["consent_utc"] == "2026-11-20T10:00:00Z" and row["consent_recorded_utc"] > row["consent_utc"]
    assert pairplay_cli("participant", "export", folder, "p01").returncode == 0
    with zipfile.ZipFile(folder / "exports" / "p01.zip") as z:
        [exported] = list(csv.DictReader(io.StringIO(z.read("participant.csv").decode())))
        assert exported["consent_utc"] == "2026-11-20T10:00:00Z" and exported["consent_recorded_utc"]
        assert "given 2026-11-20T10:00:00Z (recorded " in z.read("README.txt").decode()
    lines = len(journal(folder))
    assert "is in the future" in one_line(pairplay_cli("protocol", "consent", folder, "p02", "--given-at", "2099-01-01"))
    assert "not an ISO time" in one_line(pairplay_cli("protocol", "consent", folder, "p02", "--given-at", "yesterday"))
    assert len(journal(folder)) == lines


def test_a_persons_step_waiting_for_consent_says_so_in_the_console(tmp_path):
    data = StudyData.create(tmp_path / "study", study_with_form(tmp_path))
    data.register_many("phase1", count=2)
    data.record_consent("p02")
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        server = ConsoleServer(runner).start()
        try:
            _, state = call(f"{server.url}/api/console/state?token={server.token}")
            waits = {(p["participant"], p["game"]): p["waits"] for p in state["plan"] if p["kind"] == "play"}
            assert waits[("p01", 0)] == "no consent recorded" and waits[("p02", 0)] == "", waits
            assert state["next"]["waits"] == "no consent recorded"
            problems = {p["id"]: p["consent_problem"] for p in state["participants"]}
            assert problems == {"p01": "no consent recorded", "p02": ""}, problems
            data.change_consent_form("v3")  # p02 consented to v2 only: waits again, and the page says why
            _, state = call(f"{server.url}/api/console/state?token={server.token}")
            assert state["consent_form"] == "v3"
            assert state["participants"][1]["consent_problem"] == \
                "consent to 'v2 2026-11' only, the study's consent form is now 'v3'", state["participants"]
            runner.scripted = {"p01": "blind"}  # serve --pilot p01=blind: a persona needs none
            _, state = call(f"{server.url}/api/console/state?token={server.token}")
            assert state["next"]["waits"] == ""
        finally:
            server.close()


def test_consent_withdrawn_is_refused_for_a_person_whose_consent_was_never_recorded(tmp_path, pairplay_cli):
    data = StudyData.create(tmp_path / "study", study_with_form(tmp_path))
    data.register_many("phase1", count=1)
    before = (data.folder / "journal.jsonl").read_bytes()
    err = one_line(pairplay_cli("participant", "delete", data.folder, "p01", "--yes", "--consent-withdrawn"))
    assert "p01 has no consent recorded: there is none to withdraw" in err and "--given-at" in err, err
    assert (data.folder / "journal.jsonl").read_bytes() == before  # nothing deleted, nothing journaled


def test_a_participant_named_twice_in_pilot_is_refused(tmp_path, pairplay_cli):
    data = StudyData.create(tmp_path / "study", study_with_form(tmp_path))
    data.register_many("phase1", count=2)
    err = one_line(pairplay_cli("protocol", "serve", data.folder, "--pilot", "p01=blind,p01=deaf"))
    assert "p01 named twice (--pilot)" in err, err


def test_repair_of_a_torn_consent_names_it_and_writes_the_tables_again(tmp_path, pairplay_cli):
    folder = tmp_path / "study"
    assert pairplay_cli("protocol", "init", folder, "--study", study_with_form(tmp_path)).returncode == 0
    assert pairplay_cli("protocol", "register", folder, "--count", "2", "--consent").returncode == 0
    path = folder / "journal.jsonl"
    path.write_bytes(path.read_bytes()[:-40])  # p02's ConsentGiven cut by a crash
    assert [r["consent_form"] for r in table(folder / "participants.csv")] == ["v2 2026-11", "v2 2026-11"]
    r = pairplay_cli("protocol", "repair", folder)
    assert r.returncode == 0, r
    assert "the cut line was p02's consent (ConsentGiven): it is not recorded now; record it again " \
           f"(`pairplay protocol consent {folder} p02`)" in r.stdout, r.stdout
    assert [(r["participant"], r["consent_form"]) for r in table(folder / "participants.csv")] == \
        [("p01", "v2 2026-11"), ("p02", "")]
    assert pairplay_cli("protocol", "consent", folder, "p02").returncode == 0
    assert json.loads(path.read_text().splitlines()[-1])["participant"] == "p02"


def test_the_console_records_a_consent_held_on_paper_as_given_then(browser, tmp_path):
    """The console's Record consent takes when they signed, parsed as `protocol consent --given-at` parses it (one
    parser, pairplay/isotime.py): before, it had no such field and a consent held on paper was journaled "now",
    after the games it covered (trial33 D)."""
    import argparse

    from pairplay.cli.args import time_ns
    data = StudyData.create(tmp_path / "study", study_with_form(tmp_path))
    data.register_many("phase1", count=3)
    made_earlier(data.folder)
    data = StudyData(data.folder)
    with Bus(BusOptions()) as bus:
        server = ConsoleServer(StudyRunner(data, bus)).start()
        ctx = browser.new_context(viewport={"width": 1366, "height": 900}, bypass_csp=True)
        try:
            console = ctx.new_page()
            errors = []
            console.on("pageerror", lambda e: errors.append(str(e)))
            console.goto(server.console_url)
            console.wait_for_function("document.querySelectorAll('#participants li').length == 3", timeout=10000)

            def record(pid: str, given_at: str) -> None:
                console.select_option("#data-participant", pid)
                console.fill("#consent-given-at", given_at)
                console.click("#record-consent")

            def refusal(naming: str) -> str:
                # the refusal of this record, not the one before it still on screen (the same class)
                console.wait_for_function("t => document.getElementById('message').className === 'error' && "
                                          "document.getElementById('message').textContent.includes(t)", arg=naming,
                                          timeout=10000)
                return console.inner_text("#message")

            record("p01", "2026-11-20T10:00Z")
            console.wait_for_function("document.querySelector('#participants li').textContent.includes('recorded ')",
                                      timeout=10000)
            shown = console.inner_text("#participants li")
            assert "consent: form 'v2 2026-11' given 2026-11-20T10:00:00Z (recorded 20" in shown, shown
            assert console.input_value("#consent-given-at") == ""  # not carried over to the next person
            [given] = [e for e in journal(data.folder) if e["event"] == "ConsentGiven"]
            assert given["participant"] == "p01" and given["given_ns"] == 1795168800 * 10**9
            # what the CLI refuses, the console refuses in the same words; nothing journaled
            lines = len(journal(data.folder))
            for text in ("yesterday", "20-11-2026"):
                try:
                    time_ns(text)
                    raise AssertionError(f"the CLI takes {text!r}")
                except argparse.ArgumentTypeError as err:
                    cli_words = str(err)
                record("p02", text)
                said = refusal(text)
                assert said == f"when they signed (`given_at`): {cli_words}", said
            record("p02", "2099-01-01")
            said = refusal("2099-01-01")
            assert "p02: consent given at 2099-01-01" in said and "is in the future" in said
            record("p02", "2016-11-20T10:00Z")  # a typo of the year: before the study folder was made
            said = refusal("2016-11-20")
            assert "p02: consent given at 2016-11-20T10:00:00Z is more than a year before the study folder was made " \
                "(2026-11-01" in said
            assert len(journal(data.folder)) == lines
            record("p03", "")  # blank: given now, as without --given-at
            console.wait_for_function("document.querySelectorAll('#participants li')[2].textContent.includes('given ')",
                                      timeout=10000)
            assert "(recorded" not in console.inner_text("#participants li >> nth=2")
            assert errors == []
        finally:
            ctx.close()
            server.close()


def test_a_consent_time_before_the_study_and_a_form_it_never_had_are_refused_at_every_door(tmp_path, pairplay_cli):
    """Before (trial34 I): `--given-at 1970-01-01T00:00Z` was journaled given_ns 0, the "given when recorded" value,
    so the time given became now without a word; 1999 (a typo of the year) was journaled for good; `consent-form ''`
    made the unnamed form the amendment; `consent --form v9` journaled a consent to a form the study never had.
    Each is refused in one line naming what is taken, by the CLI and the console's Record consent alike, and
    nothing is journaled."""
    folder = tmp_path / "study"
    assert pairplay_cli("protocol", "init", folder, "--study", study_with_form(tmp_path)).returncode == 0
    assert pairplay_cli("protocol", "register", folder, "--count", "3").returncode == 0
    lines = len(journal(folder))
    for when in ("1970-01-01T00:00Z", "1969-12-31T23:59Z", "1999-01-01T00:00Z"):
        said = one_line(pairplay_cli("protocol", "consent", folder, "p01", "--given-at", when))
        assert f"p01: consent given at {when[:16]}:00Z is more than a year before the study folder was made (20" \
            in said, said
        assert "give the time they signed, from a year before then up to now" in said
    # a form signed at recruitment, a month before the folder was made, is a study's everyday case: taken
    import datetime
    month_before = (datetime.datetime.now() - datetime.timedelta(days=30)).strftime("%Y-%m-%dT%H:%M")
    ran = pairplay_cli("protocol", "consent", folder, "p03", "--given-at", month_before)
    assert ran.returncode == 0, ran.stderr
    lines += 1
    said = one_line(pairplay_cli("protocol", "consent", folder, "p01", "--form", "v9"))
    assert "consent form 'v9' is not one this study has had ('v2 2026-11'): give the version they signed" in said
    said = one_line(pairplay_cli("protocol", "consent-form", folder, ""))
    assert "consent form '': an amendment names the new form's version" in said, said
    assert len(journal(folder)) == lines
    assert pairplay_cli("protocol", "consent-form", folder, "v3").returncode == 0
    r = pairplay_cli("protocol", "consent", folder, "p01", "--form", "v2 2026-11")  # an earlier form: one it had
    assert r.returncode == 0 and "form 'v2 2026-11'" in r.stdout, r

    data = StudyData(folder)
    with Bus(BusOptions()) as bus:
        server = ConsoleServer(StudyRunner(data, bus)).start()
        try:
            lines = len(journal(folder))
            status, said = call(f"{server.url}/api/console/consent?token={server.token}",
                                {"participant": "p02", "given_at": "1970-01-01T00:00Z"})
            assert status == 400 and "p02: consent given at 1970-01-01T00:00:00Z is more than a year before the " \
                "study folder was made" in json.dumps(said), said
            assert len(journal(folder)) == lines
        finally:
            server.close()
