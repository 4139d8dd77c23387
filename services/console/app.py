"""The console's routes: the experimenter's page and API, and the participant's questionnaire page.

Rule: every console route needs the experimenter token (`?token=` or the
`X-Pairplay-Token` header), compared in constant time; a wrong one gets 403 and
nothing else. The questionnaire routes need the running game's own
questionnaire token instead (the link's `?session=&token=`, checked before a
body is read), which is useless once the answers are in. Every body is at most
64 KiB: the lab app refuses a longer one before any route (lab/bodylimit.py). A
request the study refuses (a step out of order, a bad answer, an abort without
a reason) is answered 400 with `{"error": "<one line>"}`; nothing a request
sends can raise out of a route. Steps (a game, a combination, a report) run in
a background thread, one at a time (the runner refuses a second), and the page
follows them by polling `/api/console/state` (what it shows: the plan, the
running game's round, picks, last suggestion and robot action, the learning
curve so far, the combination's profiles and per-state rules).
"""

from __future__ import annotations

import hmac
import logging
import threading
from dataclasses import asdict
from pathlib import Path

import msgspec
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from pairplay.core.actions import ACTION_NAMES
from pairplay.core.geometry import N_STATES, STATE_NAMES
from pairplay.isotime import iso_time_ns
from pairplay.outputs import output_folder
from pairplay.replay import biases
from pairplay.replay.studydata import StudyDataError, consent_words, mentions, named
from pairplay.schemas.jsonfile import in_words

from pairplay.services.protocol import Live, StudyRunner
from pairplay.numbers import counted
from pairplay.schemas.nesting import json_decode

log = logging.getLogger("pairplay.console")
STATIC = Path(__file__).parent / "static"


class Console:
    """The console's state around a StudyRunner: the step running in the background and its outcome."""

    def __init__(self, runner: StudyRunner, token: str, board_url=None):
        self.runner, self.token = runner, token
        self.data = runner.data
        self.thread: threading.Thread | None = None
        self.last = {"step": "", "ok": True, "message": ""}
        # board_url(session) -> the board page's URL for the running game (the lab server's), or None
        self.board_url = board_url

    # -- background steps ----------------------------------------------------
    def busy(self) -> bool:
        return self.thread is not None and self.thread.is_alive()

    def start(self, label: str, work) -> None:
        if self.busy():
            raise StudyDataError(f"a step is already running ({self.last['step']})")

        def run() -> None:
            try:
                result = work()
                robot = self.runner.delivery.get(getattr(result, "session", ""), "")
                self.last = {"step": label, "ok": True,
                             "message": _describe(result, self.data) + (f"; {robot}" if robot else "")}
            except StudyDataError as err:
                self.last = {"step": label, "ok": False, "message": str(err)}
            except Exception as err:  # a step must never take the console down with it
                log.exception("step %s failed", label)
                self.last = {"step": label, "ok": False, "message": f"{type(err).__name__}: {err}"}
        self.last = {"step": label, "ok": True, "message": "running"}
        thread = threading.Thread(target=run, name="pairplay-console-step", daemon=True)
        try:
            thread.start()
        except RuntimeError as err:  # out of threads (`ulimit -v`): the step is said failed, as any other
            self.last = {"step": label, "ok": False, "message": f"the step could not start: {err}"}
            return
        self.thread = thread  # only once started: the server's shutdown joins it

    def forget(self, pid: str) -> None:
        """After `pid`'s deletion: the page shows nothing of theirs it held beside the journal (their last game's
        live panel, the outcome line of a step of theirs, an abort's reason in it), as the study folder keeps
        none (docs/study.md: a deletion)."""
        if self.runner.live.participant == pid:  # their game is over (a running one is not deleted)
            self.runner.live = Live()
        if mentions(f"{self.last['step']} {self.last['message']}", pid):
            self.last = {"step": "", "ok": True, "message": ""}

    # -- what the page shows -------------------------------------------------
    def state(self) -> dict:
        data, live = self.data, self.runner.live
        plan = [{"kind": s.kind, "phase": s.phase, "participant": s.participant, "game": s.game, "done": s.done,
                 "blocked": s.blocked, "label": s.label, "note": s.note,
                 # a person's game waits for their consent; one a persona plays here (serve --pilot) does not
                 "waits": "" if s.participant in self.runner.scripted else s.waits} for s in data.plan()]
        step = data.next_step()  # none while nobody is registered: the page says to register first
        nxt = next((p for p in plan if step is not None and p["label"] == step.label), None)
        games = [{"session": g.session, "participant": g.participant, "phase": g.phase, "game": g.game + 1,
                  "outcome": g.ended.outcome if g.ended else "running", "reason": g.ended.reason if g.ended else "",
                  "rounds": g.ended.rounds_played if g.ended else 0, "invalid": g.invalid,
                  "questionnaire": bool(g.ended and g.ended.questionnaire), "scripted": g.scripted,
                  # the bias policy it was played on, and what is wrong with it (replay/biases.py): it stays valid
                  "bias": g.bias, "bias_flawed": data.bias_flaw(g)}
                 for g in data.state.games.values()]
        combined = {}
        for phase, c in data.state.combined.items():
            names = data.user_names(c)  # a persona as what it is, not the `human:<id>` its session ran as
            combined[phase] = {
                "users": [names.get(u, u) for u in c.users], "output": c.output,
                "profiles": {names.get(u, u): p for u, p in c.profiles.items()},
                "partial": f"PARTIAL profile: {c.partial}" if c.partial else "",  # as `pairplay profile` says it
                # made with a game marked invalid since: combined again into a new file (replay/biases.py); the
                # earlier files of the phase, kept for the games played on them, each with what is wrong with it
                "flawed": biases.flaw_words(data.state, c),
                "earlier": [{"output": e.output, "flawed": biases.flaw_words(data.state, e),
                             "played_on": [g.session for g in biases.played_on(data.state, e)]}
                            for e in biases.versions(data.state, phase)[:-1]],
                "states": [{"state": f"{s} {STATE_NAMES[s]}", "action": f"{a}: {ACTION_NAMES[a]}",
                            "rule": named(r, names)}
                           for s, (a, r) in enumerate(zip(c.actions, c.decided_by)) if s < N_STATES - 1]}
        live_d = asdict(live)
        live_d.pop("questionnaire_token")
        hub = self.runner.lab.hubs.get(live.session) if self.runner.lab is not None and live.session else None
        if hub is not None:  # the lab serves the board: "connected" is a board page on its WebSocket, not the
            # lab's board service joining the bus (it does before any page is open)
            live_d["board"] = any(c.page == "board" for c in list(hub.clients))
        if live.session and live.questionnaire_token and live.state in ("playing", "questionnaire"):
            live_d["questionnaire_url"] = f"/questionnaire?session={live.session}&token={live.questionnaire_token}"
        if live.session and self.board_url is not None and live.state == "playing":
            url = self.board_url(live.session)  # None until the lab's board for this game is up
            if url:  # a key only with a URL to open (a client waiting for "board_url" got null and failed)
                live_d["board_url"] = url
        # ids a record shows given that the journal does not register (a crash, a hand edit): listed as what they
        # are, beside the participants, so that the experimenter sees the inconsistency (`protocol status` says it too)
        notes, key_problem = data.id_notes()
        return {
            "unregistered": [{"id": pid, "note": note} for pid, note in notes.items()], "key_file_problem": key_problem,
            "robot_warning": self.runner.robot_warning,
            "study": {"id": data.study.study.id, "title": data.study.study.title, "folder": str(data.folder),
                      "phases": [p.id for p in data.study.phase], "key_file": bool(data.key_file)},
            "participants": [{"id": pid, "joins": r.joins, "scripted": data.scripted_as(pid),
                              "games": sum(1 for g in data.games_of(pid) if g.valid_complete),
                              "consent": consent_words(data.state.consent[pid]) if pid in data.state.consent else "",
                              # why a person's game waits ("" if it does not): none, or to an earlier form only
                              "consent_problem": data.consent_problem(pid)}
                             for pid, r in data.state.participants.items()],
            "consent_form": data.consent_form,  # the study's form now (`protocol consent-form`)
            "plan": plan, "next": nxt, "games": games, "combined": combined, "live": live_d,
            "busy": self.busy(), "last": self.last, "deletions": len(data.state.deletions),
            "report": (data.folder / "report" / "report.md").is_file(),
        }


def _describe(result, data=None) -> str:
    if result is None:
        return "done"
    if hasattr(result, "ended") and getattr(result, "ended", None) is not None:
        e = result.ended
        return f"{result.session}: {e.outcome}" + (f" ({e.reason})" if e.reason else "") + f", {counted(e.rounds_played, 'round')}"
    if hasattr(result, "users"):
        return (f"bias policy of {result.phase}: {counted(len(result.users), 'user')} "
                + (biases.combined_words(data.state, result) if data is not None else f"combined into {result.output}"))
    return str(result)


async def _body(request: Request) -> dict:
    """The request's JSON object ({} for no body): at most 64 KiB, the lab app's BodyLimit refused a longer one
    before any route or token check (services/lab/bodylimit.py)."""
    raw = await request.body()
    if not raw:
        return {}
    try:
        body = json_decode(raw)
    except msgspec.DecodeError:
        raise StudyDataError("the request is not JSON") from None
    if not isinstance(body, dict):
        raise StudyDataError("the request must be a JSON object")
    return body


class _Request(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """A console request's JSON body: a key it does not know is refused, as in every file pairplay reads."""


class RegisterRequest(_Request):
    phase: str | None = None  # the first phase's by default
    count: int = 1
    label: str = ""  # a name for the key file: one participant only
    consent: bool = False  # they signed the study's consent form now: recorded (ConsentGiven)


class ControlRequest(_Request):
    reason: str = ""
    session: str = ""  # "invalid": the session to mark


class ParticipantRequest(_Request):
    participant: str = ""
    confirm: str = ""  # a deletion: the participant's id typed again
    consent_withdrawn: bool = False  # a deletion because the person withdrew their consent: the journal says so


class ConsentRequest(_Request):
    participant: str = ""
    # when they signed, if before now (a consent held on paper), as `protocol consent --given-at` takes it
    # (pairplay/isotime.py, one parser for both); "" is now
    given_at: str = ""


class AnswerRequest(_Request):
    session: str = ""
    token: str = ""
    answers: object = None  # checked item by item by the runner, which knows the questionnaire


def _read(body: dict, kind: type[_Request]) -> _Request:
    """`body` as `kind`, or StudyDataError in the file readers' words ("count: must be an integer, got text";
    "no key `lable` is known here (did you mean `label`?)")."""
    try:
        return msgspec.convert(body, kind)
    except msgspec.ValidationError as err:
        raise StudyDataError(in_words(err, kind)) from None


def console_routes(console: Console) -> list:
    """The routes of the console and the questionnaire page, to mount in the lab server's Starlette app."""
    runner, data = console.runner, console.data

    def authorised(request: Request) -> bool:
        given = request.query_params.get("token") or request.headers.get("x-pairplay-token", "")
        return hmac.compare_digest(given.encode(), console.token.encode())

    def guarded(handler):
        async def route(request: Request) -> Response:
            if not authorised(request):
                return JSONResponse({"error": "wrong or missing experimenter token"}, status_code=403)
            try:
                return await handler(request)
            except StudyDataError as err:
                return JSONResponse({"error": str(err)}, status_code=400)
            except Exception as err:  # malformed input must not take the lab down
                log.exception("console request failed")
                return JSONResponse({"error": f"{type(err).__name__}: {err}"}, status_code=400)
        return route

    async def page(request: Request) -> Response:
        return FileResponse(STATIC / "console.html")

    async def state(request: Request) -> Response:
        return JSONResponse(console.state())

    async def register(request: Request) -> Response:
        asked = _read(await _body(request), RegisterRequest)
        ids = data.register_many(asked.phase or data.study.phase[0].id, asked.count, asked.label,
                                 count_name="`count`", label_name="a name (`label`)", consent=asked.consent)
        data.write_tables()
        return JSONResponse({"registered": ids, "consent": asked.consent})

    async def consent(request: Request) -> Response:
        asked = _read(await _body(request), ConsentRequest)
        try:  # the CLI's parser: the same texts taken, the same refused in the same words
            given_ns = iso_time_ns(asked.given_at) if asked.given_at.strip() else None
        except ValueError as err:
            raise StudyDataError(f"when they signed (`given_at`): {err}") from None
        given = data.record_consent(asked.participant, given_ns=given_ns)  # the future, the past before the study refused there, as for the CLI
        data.write_tables()
        return JSONResponse({"consent": asked.participant, "form": given.form, "given": consent_words(given)})

    async def start_next(request: Request) -> Response:
        step = data.next_step()
        if step is None:
            raise StudyDataError("the plan is complete" if data.state.participants else
                                 "nobody is registered: register participants first")
        if step.blocked:
            raise StudyDataError(f"{step.label}: {step.blocked}")
        if step.kind == "combine":
            console.start(step.label, lambda: runner.combine(step.phase))
        else:
            runner.check_step(step.participant, step.phase, step.game)
            if step.participant not in runner.scripted:  # a person's game: refused now, not in the step's thread
                data.check_consent(step.participant)
            console.start(step.label, lambda: runner.run_game(step.participant, step.phase, step.game))
        return JSONResponse({"started": step.label})

    async def control(request: Request) -> Response:
        asked = _read(await _body(request), ControlRequest)
        action = request.path_params["action"]
        if action == "pause":
            runner.pause(asked.reason)
        elif action == "resume":
            runner.resume()
        elif action == "abort":
            runner.abort(asked.reason)
        elif action == "skip-questionnaire":
            runner.skip_questionnaire()
        elif action == "invalid":  # said as `protocol mark-invalid` says it: what it did to a bias policy too
            return JSONResponse({"ok": action, "said": data.marked_line(data.mark_invalid(asked.session, asked.reason))})
        else:
            raise StudyDataError(f"no action {action!r}")
        return JSONResponse({"ok": action})

    async def export(request: Request) -> Response:
        asked = _read(await _body(request), ParticipantRequest)
        left_out: list[str] = []  # a running game's files: not in the zip, and said (its README says it too)
        path = data.export_participant(asked.participant, force=True, left_out=left_out)
        return JSONResponse({"export": f"/api/console/exports/{path.name}", "left_out": [
            f"{session}: running: its files are left out; export again after its end" for session in left_out]})

    async def download(request: Request) -> Response:
        name = request.path_params["name"]
        path = data.folder / "exports" / name
        if not name.endswith(".zip") or "/" in name or not path.is_file():
            return JSONResponse({"error": "no such export"}, status_code=404)
        return FileResponse(path, filename=name, media_type="application/zip")

    async def delete(request: Request) -> Response:
        asked = _read(await _body(request), ParticipantRequest)
        pid = asked.participant
        if asked.confirm != pid:
            raise StudyDataError("type the participant's id to confirm the deletion")
        erased = data.delete_participant(pid, consent_withdrawn=asked.consent_withdrawn)
        console.forget(pid)
        return JSONResponse({"deleted": msgspec.to_builtins(erased.event), "not_erased": erased.elsewhere,
                             "erased_copies": [c.path for c in erased.copies if c.erased], "unnamed": erased.unnamed, "no_key_line": erased.no_key_line,
                             "kept": [{"file": rel, "names_them": names} for rel, names in erased.left]})

    async def report(request: Request) -> Response:
        from pairplay.report.human import HUMAN_MANIFEST, HUMAN_OUTPUTS, human_report

        def work():
            out = data.folder / "report"
            with output_folder(out, force=True, owned=HUMAN_OUTPUTS, manifest=HUMAN_MANIFEST) as tmp:  # a failure leaves the old report and no temporary folder
                made = human_report(data.folder, tmp)
            kind = (f" (a rehearsal: {counted(len(made.games), 'scripted game')}, no person played)" if made.rehearsal else
                    f" ({counted(len(made.scripted), 'scripted game')} left out)" if made.scripted else "")
            return f"report written: {out / 'report.md'}{kind}"
        console.start("report", work)
        return JSONResponse({"started": "report"})

    async def report_file(request: Request) -> Response:
        name = request.path_params["name"]
        path = (data.folder / "report" / name).resolve()
        if not path.is_relative_to((data.folder / "report").resolve()) or not path.is_file():
            return JSONResponse({"error": "no such report file"}, status_code=404)
        return FileResponse(path)

    # -- the participant's questionnaire -------------------------------------
    async def q_page(request: Request) -> Response:
        return FileResponse(STATIC / "questionnaire.html")

    def questionnaire_link_ok(request: Request) -> bool:
        """The link's `?session=&token=` are the running game's and its questionnaire token is still unused."""
        live = runner.live
        token = request.query_params.get("token", "")
        return bool(live.questionnaire_token) and hmac.compare_digest(token.encode(), live.questionnaire_token.encode()) \
            and request.query_params.get("session") == live.session

    def refused_link(request: Request) -> Response:
        """403 for a link that is not the running game's questionnaire's: a link of this process's already
        answered or closed says so (`spent`: the page thanks or says closed, not an error), any other is wrong."""
        spent = runner.spent_link(request.query_params.get("session", ""), request.query_params.get("token", ""))
        said = {"answered": "your answers are recorded", "closed": "this questionnaire is closed"}
        return JSONResponse({"error": said.get(spent, "this questionnaire link is not the current game's"),
                             "spent": spent}, status_code=403)

    async def q_items(request: Request) -> Response:
        live = runner.live
        if not questionnaire_link_ok(request):
            return refused_link(request)
        name, items = runner.questions_for(live.participant, live.phase)
        q = data.study.questionnaire[name]
        return JSONResponse({"title": q.title, "intro": q.intro, "ready": live.state == "questionnaire",
                             "items": [msgspec.to_builtins(i) for i in items]})

    async def q_answer(request: Request) -> Response:
        # the link's token before the body is read, as every other route that takes a body (trial28 F13: anyone
        # who reached the port could post here); the body's session and token are the runner's to check again
        if not questionnaire_link_ok(request):
            return refused_link(request)
        try:
            asked = _read(await _body(request), AnswerRequest)
            runner.answer_questionnaire(asked.session, asked.token, asked.answers)
        except StudyDataError as err:
            return JSONResponse({"error": str(err)}, status_code=400)
        return JSONResponse({"ok": True})

    return [
        Route("/console", page),  # the page holds nothing: its API needs the token
        Route("/api/console/state", guarded(state)),
        Route("/api/console/register", guarded(register), methods=["POST"]),
        Route("/api/console/next", guarded(start_next), methods=["POST"]),
        Route("/api/console/control/{action}", guarded(control), methods=["POST"]),
        Route("/api/console/consent", guarded(consent), methods=["POST"]),
        Route("/api/console/export", guarded(export), methods=["POST"]),
        Route("/api/console/exports/{name}", guarded(download)),
        Route("/api/console/delete", guarded(delete), methods=["POST"]),
        Route("/api/console/report", guarded(report), methods=["POST"]),
        Route("/api/console/report/{name:path}", guarded(report_file)),
        Route("/questionnaire", q_page),
        Route("/api/questionnaire", q_items),
        Route("/api/questionnaire/answer", q_answer, methods=["POST"]),
        Mount("/console-static", StaticFiles(directory=STATIC), name="console-static"),
    ]
