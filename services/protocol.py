"""The protocol of a study with people (thesis 7.2), step by step, on the bus.

Rule: `StudyRunner` runs the steps of a study folder's plan (replay/studydata.py):
- a game: one recorded session (services/session.py) of a registered participant (a person only with
  their informed consent journaled, ConsentGiven; a persona in a rehearsal needs none),
  configured by its phase: `human:<id>`, the observed card is the first pick, the
  ignore rule is the pick interval with the study's window (7.1.2), the phase's
  learner preset, for pi-reuse the phase's bias policy; the recording stays open
  after the game for the phase's questionnaire (QuestionnaireAnswered from the
  board), then the game's policy is rebuilt from the recording and the journal
  says how it ended. A signal (`interrupt`) leaves no time to read the
  recording back: a game that had completed (the signal came during its
  questionnaire) is journaled completed without its policy, which the
  folder's next serve, pilot or report builds from the recording
  (StudyData.build_missing_policies); one that had not is aborted. Who touches the cards is not this module's business: the
  board page of the lab server, or a `ScriptedPlayer` (services/scripted.py) for
  pilots and tests.
- a combination: a CombineRequested to the combiner service (services/combiner.py)
  naming the policy files of the earlier phase's valid games; its PolicyCombined
  (the merged greedy policy and the rule that decided each state) and every
  user's profile (algorithm 3, over the same files) are journaled. Each writes a
  file of its own (replay/biases.py): one made again, after a game it took was
  marked invalid, keeps the earlier one for the games played on it.
Steps run one at a time. Pause, resume and abort are the experimenter's events
on the game's bus (SessionPaused, SessionResumed, SessionAborted, source
"experimenter"): the game obeys them (it refuses touches while paused, ends the
session on an abort) and the recording holds them, so a replay decides the
same; the journal says it too. `mark_invalid` keeps a game out of the plan's
done steps, the combination and the report (a combination that took it is made again).
"""

from __future__ import annotations

import logging
import re
import secrets
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from pairplay import __version__, signals, testpause
from pairplay.errors import unshowable
from pairplay.core.policies import partial_inputs, users_from_policies
from pairplay.replay import biases
from pairplay.replay.delivery import delivery_counts, delivery_line, troubled
from pairplay.replay.reader import events_of
from pairplay.replay.studydata import (Game, StudyData, StudyDataError, game_end, journaled_or_removed, one_line,
                                       recording_damage, refuse_control)
from pairplay.schemas import events as ev
from pairplay.schemas import journal as j
from pairplay.schemas.envelope import stamped
from pairplay.schemas.keys import event_key
from pairplay.schemas.policy import read_policy
from pairplay.schemas.session import SessionConfig, learner_overrides
from pairplay.schemas.trust import MAX_PAYLOAD, MAX_REASON

from pairplay.services import biasfile
from pairplay.services.bus import Bus, BusClosed, pass_stop, shutdown_wait
from pairplay.services.combiner import CombinerLogic
from pairplay.services.recorder import RecordingExists, check_new_recording
from pairplay.services.robot.choice import NO_ROBOT, RobotChoice
from pairplay.services.runner import Node
from pairplay.services.session import run_session
from pairplay.numbers import counted

log = logging.getLogger("pairplay.protocol")
# how long a process stopped by a signal waits for its running game's end to be journaled (`wait_journaled`): what
# the machine needs to finish the recording and write the journal at load 15+ is seconds; a write that never comes
# (a hung disk) held it for ever
JOURNALED_WAIT_S = 20.0


@dataclass
class Running:
    """The game being played: its session, recording (as the study folder was given), rounds and run_session's
    summary (filled as the session stops: started, ended, rounds_played, events)."""
    session: str
    path: Path
    rounds: int
    summary: dict


@dataclass
class Live:
    """What the console shows of the running game, folded from its events as they pass."""
    session: str = ""
    participant: str = ""
    phase: str = ""
    game: int = 0
    rounds: int = 0
    round: int = 0
    picks: int = 0
    picks_per_round: list[int] = field(default_factory=list)
    suggestion: str = ""
    robot: str = ""
    paused: bool = False
    # the game's first RoundStarted seen: it is on the bus and takes the experimenter's controls. A pause sent
    # before (the game not yet subscribed) reached nobody, was answered ok and shown paused while the game played
    # every round, and its Resume was refused "not paused" (trial35 F1)
    started: bool = False
    state: str = "idle"  # idle | playing | questionnaire | ended (aborted: no questionnaire) | combining
    # a board (a scripted player, or a board elsewhere) is on the game's bus; when the lab serves the board,
    # the console says a board page is connected instead (services/console/app.py)
    board: bool = False
    questionnaire_token: str = ""  # the per-game token of the questionnaire page
    scripted: str = ""  # the persona playing instead of a person (a rehearsal): the console says so
    board_token: str = ""  # the board page's token (the same, when there is a questionnaire)
    # MessageRejected of the game (a page's late or stale touch, a malformed message): how many, the last's reason;
    # before, the console showed none (trial32 G: a board whose every touch was refused as late, and no word)
    refused: int = 0
    last_refused: str = ""

    def see(self, e: ev.Event) -> None:
        name = type(e).__name__
        if name == "RoundStarted":
            self.round, self.picks, self.started = e.round, 0, True
        elif name == "CardRevealed":
            self.picks += 1
        elif name == "SuggestionMade":
            self.suggestion = f"{e.action}: {e.action_name} ({e.chosen_by}, epsilon {e.epsilon:.2f})"
        elif name == "RobotActed":
            # its reason with it: "failed" alone said nothing of an unreachable robot (trial27 F13)
            self.robot = f"{e.backend}: {e.outcome}" + (f" ({e.error})" if e.error else "") \
                + f" {', '.join(e.commands)[:120]}"
        elif name == "RoundEnded":
            self.picks_per_round.append(2 * e.turns)
        elif name == "SessionEnded":
            if e.reason == "aborted":  # an aborted game asks nothing: its questionnaire link is dead (403)
                self.state, self.questionnaire_token = "ended", ""
            else:
                self.state = "questionnaire"
        elif name == "ServiceStarted" and e.service == "board":
            self.board = True
        elif name == "MessageRejected":
            self.refused += 1
            self.last_refused = e.reason[:200]  # a line of the console's panel, not the record


class StudyRunner:
    def __init__(self, data: StudyData, bus: Bus, robot: RobotChoice | None = None,
                 questionnaire_timeout_s: float = 3600.0, lab=None):
        self.data, self.bus = data, bus
        # the lab server's sessions (services/lab/app.Lab): each game's board is served there
        self.lab = lab
        # a dress rehearsal: participant id -> core persona that plays instead of a person (services/scripted.py)
        self.scripted: dict[str, str] = {}
        self.rehearsal = False  # `protocol pilot`: every game scripted, the combination takes them (run_plan's players)
        url = data.study.study.robot
        self.robot = robot if robot is not None else (None if url == NO_ROBOT else RobotChoice(url))
        self.questionnaire_timeout_s = questionnaire_timeout_s
        self.live = Live()
        # the robot not accepting a connection when the verb started (cli/protocol.py warn_unreachable): shown by
        # the console too, not only on the terminal, which the experimenter at the console may not see
        self.robot_warning = ""
        self.delivery: dict[str, str] = {}  # session -> what its robot delivered (replay/delivery.py)
        # a WARNING when a game's robot did not get every suggestion; off where each game's line says it already
        # (`protocol pilot`: the line came twice, a WARNING and the step's, for every game: a new user's trial)
        self.warns_undelivered = True
        self._stop: threading.Event | None = None
        self.interrupted: threading.Event | None = None  # the process's signal (interrupt): no more steps
        self._skip = threading.Event()
        self._abort_reason = ""
        self._busy = threading.Lock()
        # set while no game's end is owed to the journal: cleared at its GameStarted, set once its GameEnded is
        # written (or the step failed); a process stopped by a signal waits for it (`wait_journaled`)
        self._journaled = threading.Event()
        self._journaled.set()
        self._control_seq = 0
        self._game_bus: Bus | None = None  # the running game's scope of `bus` (_play)
        # the game being played (_play to run_game's end), and the one the process's signal stopped (`interrupt`):
        # what serve and pilot name on their way out (cli/protocol.py `stopped_line`), its recording and summary;
        # in serve the game runs in the console's thread, so the verb's main thread learns of it only here
        self.running: Running | None = None
        self.stopped: Running | None = None
        # every questionnaire link this process gave (token -> its session) and the ones answered: a link no longer
        # the current game's is told apart from one that never was (`spent_link`; trial27 F12b: a participant who
        # reloaded the page after sending saw "this questionnaire link is not the current game's", as an error)
        self._links: dict[str, str] = {}
        self._answered: set[str] = set()

    # -- a game --------------------------------------------------------------
    def config_for(self, pid: str, phase_id: str, game: int, scripted: str = "") -> SessionConfig:
        study, phase = self.data.study, self.data.study.phase_by_id(phase_id)
        actions: list[int] = []
        if phase.bias:
            combined = self.data.state.combined.get(phase.id)
            if combined is None:
                raise StudyDataError(f"{phase.id} reuses the bias policy of {phase.bias}: combine it first")
            if biases.flawed(self.data.state, phase.id) is not None:  # (the plan blocks it too: check_step)
                raise StudyDataError(f"{phase.id}'s bias policy {combined.output} was "
                                     f"{biases.flaw_words(self.data.state, combined)}: combine it again first")
            actions = list(combined.actions)
        config = SessionConfig(
            session=self.data.session_id(pid, phase_id, game), participant=f"human:{pid}", seed=study.study.seed,
            rounds=phase.rounds, game_index=self.data.game_index(pid, phase_id, game), algorithm=phase.algorithm,
            observed_source="first-pick", ignore_rule="time", ignore_window_ms=float(study.study.ignore_window_ms),
            ignore_clock=study.study.ignore_clock, turn_back_ms=float(study.study.turn_back_ms),
            policy_actions=actions, learner=learner_overrides(study.learner_config(phase)),
            software_version=__version__, scripted=scripted)
        config.validate()
        return config

    def check_step(self, pid: str, phase_id: str, game: int) -> None:
        """Refuse a game the plan does not allow now (StudyDataError)."""
        for step in self.data.plan():
            if step.kind == "play" and (step.participant, step.phase, step.game) == (pid, phase_id, game):
                if step.done:
                    raise StudyDataError(f"{step.label} is already played")
                if step.blocked:
                    raise StudyDataError(f"{step.label}: {step.blocked}")
                return
        self.data.participant(pid)
        raise StudyDataError(f"{pid} does not play game {game + 1} of {phase_id}")

    def questions_for(self, pid: str, phase_id: str) -> tuple[str, list]:
        """(questionnaire name, the items `pid` is asked after a game of `phase_id`): ("", []) for a phase
        without one; its items can be none (all asked of the others): then nothing is asked or waited for."""
        phase = self.data.study.phase_by_id(phase_id)
        if not phase.questionnaires:
            return "", []
        name = phase.questionnaires[0]
        return name, self.data.study.questions(name, self.data.returning(pid, phase_id))

    def run_game(self, pid: str, phase_id: str, game: int, player=None,
                 on_event: Callable[[ev.Event], None] | None = None) -> Game:
        """Play one game to its end (or abort); return its journaled state.

        `player`: a logic that plays as the board (ScriptedPlayer); None: the
        board page of the lab server does. StudyDataError if the plan refuses."""
        if not self._busy.acquire(blocking=False):
            raise StudyDataError(f"a step is already running ({self.live.session or self.live.state})")
        try:
            self.check_step(pid, phase_id, game)
            if player is None and pid in self.scripted:
                player = scripted_players(self, self.scripted)(pid, phase_id, game)
            if player is None:  # a person plays, on the board: only with their informed consent recorded
                self.data.check_consent(pid)  # (a persona needs none: no person, no personal data)
            scripted = scripted_persona(player)
            config = self.config_for(pid, phase_id, game, scripted)
            phase = self.data.study.phase_by_id(phase_id)
            recording = f"recordings/{config.session}.mcap"
            try:  # a recording the journal does not know (a copied folder, a game cut before its journal line)
                # named as the study folder was given (it named the resolved path)
                check_new_recording(self.data.given / recording, hint="the journal does not list it; move it away")
            except RecordingExists as err:
                raise StudyDataError(err.line()) from None
            combined = self.data.state.combined.get(phase_id)
            self._journaled.clear()
            self.data.append(j.GameStarted(participant=pid, phase=phase_id, game=game, session=config.session,
                                           recording=recording, bias=combined.output if combined else "",
                                           scripted=scripted))
            try:
                return self._play(config, phase, recording, player, on_event)
            except Exception as err:  # the journal never keeps a started game without its end
                if config.session in self.data.state.games and self.data.state.games[config.session].ended is None:
                    why = f"the game failed: {one_line(err)}"
                    log.error("%s: %s", config.session, why)
                    self.data.append(j.GameEnded(session=config.session, participant=pid, outcome="aborted",
                                                 reason=why, rounds_played=0, policy="", questionnaire=False))
                    self.data.write_tables()
                    raise StudyDataError(f"{config.session}: {why}") from err
                raise
        finally:
            self.live.state = "idle"
            self.live.questionnaire_token = ""  # the game is over: no questionnaire link of it works now
            self.running = None
            self._journaled.set()
            self._busy.release()

    def wait_journaled(self, timeout_s: float | None = None) -> bool:
        """Wait until the running game's end is journaled (at once if none is running); whether it was. The
        process's own last fact, written as soon as its session has stopped (`_play`): every wait before it takes
        its time from the signal's deadline, so this takes what the machine needs to write the file and the
        journal, not what another process does, up to `timeout_s` (JOURNALED_WAIT_S: a journal write that never
        comes, a hung disk, held the process for ever); a second signal, SIGINT or SIGTERM, cuts it
        (KeyboardInterrupt: pairplay/signals.py `wait_cut`; a second SIGTERM was not heard)."""
        return signals.wait_cut(self._journaled, JOURNALED_WAIT_S if timeout_s is None else timeout_s)

    def _play(self, config: SessionConfig, phase, recording: str, player, on_event) -> Game:
        """The started game (journaled GameStarted) played to its end; its GameEnded journaled."""
        pid, phase_id, game = config.participant.split(":", 1)[1], phase.id, self.data.state.games[config.session].game
        token = secrets.token_urlsafe(18)
        # what this participant is asked, not whether the phase names a questionnaire: one whose items are all
        # for the others (`ask = "returning"` for a new participant) asks nothing, and nothing is waited for
        asks = bool(self.questions_for(pid, phase_id)[1])
        if asks:
            self._links[token] = config.session
        self.live = Live(session=config.session, participant=pid, phase=phase_id, game=game,
                         rounds=config.rounds, state="playing", board=player is not None, scripted=config.scripted,
                         questionnaire_token=token if asks else "", board_token=token)
        hub = None
        if player is None and self.lab is not None:
            from pairplay.services.lab.hub import LabHub
            # the board page: /s/<session>/board?t=<token>; it turns into the questionnaire only if one is asked
            hub = self.lab.add(LabHub(config, token=token, questionnaire=asks))
        self._stop, self._abort_reason, self._control_seq = threading.Event(), "", 0
        summary: dict = {}
        self.running = Running(config.session, self.data.given / recording, config.rounds, summary)
        testpause.pause("game-set-up")
        if self.interrupted is not None:  # a signal came while this game was being set up
            self.stopped = self.stopped or self.running
            pass_stop(self.interrupted, self._stop)
        self._skip.clear()
        answered = threading.Event()
        # everything this game declares on the study's bus (the watch, the player, the session's services) is
        # on a scope of it, released at the game's end with every thread it holds (services/bus.py Bus)
        bus = self._game_bus = self.bus.scope()
        node = None
        try:
            bus.subscribe(f"pairplay/{config.session}/**", self._watcher(on_event, answered))
            if player is not None:
                node = Node(bus, player, config.session, clock=getattr(player, "clock", time.time_ns),
                            resume=False)
                node.start()
                node.run_in_thread(self._stop)
        except BaseException:
            self._game_bus = None
            bus.close(shutdown_wait(self._stop, 1.0))
            raise

        def hold(_recorder) -> None:
            if asks and not self._stop.is_set() and not self._abort_reason:
                deadline = time.monotonic() + self.questionnaire_timeout_s
                while not (answered.is_set() or self._skip.is_set() or self._stop.is_set()) \
                        and time.monotonic() < deadline:
                    time.sleep(0.02)
                time.sleep(0.05)  # the answer reaches the recorder on its own thread

        # the game waits for the board: the lab's hub, a scripted player, or a board elsewhere on the bus
        stop = self._stop
        ended = None
        try:
            path = run_session(config, self.data.folder / recording, bus=bus, stop=stop,
                               robot=self.robot, hold=hold, summary=summary,
                               wait_also=() if player is not None or hub is not None else ("board",),
                               extra_nodes=(lambda bus: [hub.make_node(bus)]) if hub is not None else None)
            if self.interrupted is not None:  # a signal: the game's end is journaled now, before the waits on
                # the board, the player and the bus below (the deadline had often run out in them: the process
                # exited without it at load ~15, and the next verb took the completed game for an interrupted one)
                ended = self._finish_interrupted(config, summary, answered.is_set())
                self._journaled.set()
        finally:  # also when the session failed to start: no board, player, subscription or thread outlives it
            if hub is not None:
                self.lab.hubs.pop(config.session, None)
                hub.close(shutdown_wait(stop, 5.0, reserve=0.3))
            stop.set()
            if node is not None:
                node.finish(shutdown_wait(stop, 5.0, reserve=0.3), shutdown_wait(stop, 0.5, reserve=0.25))
            self._game_bus = None
            bus.close(shutdown_wait(stop, 1.0, reserve=0.2))
        if ended is not None:
            return ended
        if self.interrupted is not None:  # a signal: no reading back, the process is gone within 2 s
            return self._finish_interrupted(config, summary, answered.is_set())
        return self._finish(config, path, answered.is_set())

    def _watcher(self, on_event, answered: threading.Event):
        from pairplay.schemas.events import decode_event

        def see(_key: str, payload: bytes) -> None:
            try:
                e = decode_event(payload)
            except Exception:  # the recorder rejects and records it; the console just does not show it
                return
            self.live.see(e)
            if type(e).__name__ == "QuestionnaireAnswered":
                answered.set()
            if on_event is not None:
                on_event(e)
        return see

    def signal_came(self, stop: threading.Event) -> None:
        """The process got a signal (`stop`): no step starts after it, and the game running now is the one it
        stopped (`stopped`). Plain attributes only: called in the signal's handler itself (services/bus.py
        stop_on_signals `now`), so what serve and pilot say after a second signal does not depend on whether the
        thread that runs `interrupt` got there first (it had not, once at load 5.4: pilot named no game)."""
        self.interrupted = stop
        self.stopped = self.stopped or self.running

    def interrupt(self, stop: threading.Event) -> None:
        """The process got a signal (`stop`, services/bus.py stop_on_signals): the running game stops with
        the signal's name and deadline, its recording finished; no step starts after it. Only sets flags
        (called right after the signal, services/bus.py stop_on_signals)."""
        self.signal_came(stop)
        if self._stop is not None and not self._stop.is_set():
            pass_stop(stop, self._stop)
        self._skip.set()

    def _finish_interrupted(self, config: SessionConfig, summary: dict, answered: bool) -> Game:
        """The journal's GameEnded of a game stopped by a signal, from what the session counted (its
        recording is finished; no time to read it back). A game that had completed (the signal came
        during its questionnaire, or as it ended) is journaled completed, without its policy: the next
        `protocol serve`, `pilot` or `report` builds it from the recording (StudyData.build_missing_policies).
        One that had not is aborted (`pairplay rebuild` makes its policy, flagged partial)."""
        pid = config.participant.split(":", 1)[1]
        if summary.get("ended") == "completed":
            self.data.append(j.GameEnded(session=config.session, participant=pid, outcome="completed",
                                         rounds_played=int(summary.get("rounds_played", 0)), policy="",
                                         questionnaire=answered))
        else:
            why = getattr(self.interrupted, "why", "") or "a signal"
            self.data.append(j.GameEnded(session=config.session, participant=pid, outcome="aborted",
                                         reason=f"interrupted ({why})", rounds_played=int(summary.get("rounds_played", 0)),
                                         policy="", questionnaire=answered))
        return self.data.state.games[config.session]

    def _finish(self, config: SessionConfig, path: Path, answered: bool) -> Game:
        """The game's GameEnded journaled from its recording, read back with the reader's checks (`game_end`):
        a recording that lost events gets no policy, and that is said here too, as a robot it could not reach."""
        ended = game_end(self.data.folder, config.session, config.participant.split(":", 1)[1], path, answered,
                         self._abort_reason)
        self.data.append_naming(ended, ended.policy)  # no policy file without its line (journaled_or_removed)
        # the robot's RobotActed kept as it is read, nothing else (reader.events_of)
        recorded, acted = events_of(path, only=frozenset({"SessionStarted", "RobotActed"}),
                                    tags=frozenset({"RobotActed"}))
        damaged = recording_damage(recorded)
        if damaged:
            log.warning("%s: its recording is %s: no policy built", config.session, damaged)
        if self.robot is not None:  # a robot it could not reach is said, not only under -v
            line = self.delivery[config.session] = delivery_line(acted)
            if line and self.warns_undelivered:  # a real failure is a warning, the normal summary info
                # (replay/delivery.py `troubled`): it was a WARNING for every game whose robot was ever superseded
                say = log.warning if troubled(delivery_counts(acted)[2]) else log.info
                say("%s: %s", config.session, line)
        self.data.write_tables()
        return self.data.state.games[config.session]

    # -- control -------------------------------------------------------------
    def _control(self, event: ev.Event) -> None:
        """Publish one of the experimenter's events on the running game's bus."""
        e = stamped(event, session=self.live.session, source="experimenter", seq=self._control_seq + 1,
                    time_ns=time.time_ns())
        self._put(event_key(self.live.session, "experimenter", type(event).__name__), ev.encode_event(e))
        self._control_seq += 1  # only once published: a refused event leaves no hole in the numbers

    def _put(self, key: str, payload: bytes) -> None:
        """Publish on the running game's scope of the bus (its publishers go with the game). An event over the
        bus's MAX_PAYLOAD is refused here (StudyDataError): every listener would shed it unread, and the
        experimenter be told "ok" for a pause the game never took (trial28 F20)."""
        if len(payload) > MAX_PAYLOAD:
            raise StudyDataError(f"that would be a message of {counted(len(payload), 'byte', spec=',')}, over the bus's limit "
                                 f"of {MAX_PAYLOAD:,} bytes: shorten it")
        bus = self._game_bus
        try:
            if bus is None:
                raise BusClosed("no game")
            bus.put(key, payload)
        except BusClosed:
            raise StudyDataError("no game is running") from None

    def abort(self, reason: str, grace_s: float = 5.0) -> None:
        """End the running game: the game records SessionEnded "aborted" with the reason; if it does not
        within `grace_s` (a crashed game, or a slow one on a loaded machine), the session is stopped
        anyway, its end "aborted" with the same reason."""
        if not reason.strip():
            raise StudyDataError("an abort needs a reason")
        reason = bounded_reason(reason)
        stop = self._stop
        if stop is None or self.live.state not in ("playing", "questionnaire"):
            raise StudyDataError("no game is running")
        self._abort_reason = f"aborted: {reason}"
        if self.live.state == "questionnaire":  # the game is over: just stop waiting for the answers
            self.live.questionnaire_token = ""  # the open questionnaire page is told it is closed (403)
            self._skip.set()
            return
        self._control(ev.SessionAborted(reason=reason))
        stop.aborted = reason  # the end's detail if the stop below ends the game first (session.end_reason)
        try:
            threading.Timer(grace_s, stop.set).start()
        except RuntimeError:  # out of threads (`ulimit -v`): no grace, the session is stopped now
            stop.set()

    def skip_questionnaire(self) -> None:
        if self.live.state != "questionnaire":
            raise StudyDataError("no questionnaire is awaited")
        self.live.questionnaire_token = ""  # the open questionnaire page is told it is closed (403)
        self._skip.set()

    def answer_questionnaire(self, session: str, token: str, answers: dict) -> ev.QuestionnaireAnswered:
        """Check a questionnaire page's answers against the phase's items and publish them on the game's bus
        (QuestionnaireAnswered, source "board"); StudyDataError saying what is wrong otherwise."""
        live = self.live
        if not token or token != live.questionnaire_token or session != live.session:
            raise StudyDataError("this questionnaire link is not the current game's")
        if live.state != "questionnaire":
            raise StudyDataError("the game is not over yet" if live.state == "playing" else "no questionnaire is awaited")
        name, items = self.questions_for(live.participant, live.phase)
        clean = check_answers(items, answers)
        e = stamped(ev.QuestionnaireAnswered(questionnaire=name, answers=clean), session=session, source="board",
                    seq=1, time_ns=time.time_ns())
        self._put(event_key(session, "board", "QuestionnaireAnswered"), ev.encode_event(e))
        live.questionnaire_token = ""  # one answer per game: once published (answers refused may be sent again)
        self._answered.add(token)
        return e

    def spent_link(self, session: str, token: str) -> str:
        """What became of a questionnaire link this process gave that is no longer the current game's: "answered"
        (its answers are recorded), "closed" (its game ended without them: skipped, aborted, timed out), "" if it
        is no link given here (wrong, or of an earlier process)."""
        if not token or self._links.get(token) != session:
            return ""
        return "answered" if token in self._answered else "closed"

    def pause(self, reason: str = "") -> None:
        reason = bounded_reason(reason)  # refused whatever the state: the input itself is wrong
        if self.live.state != "playing":
            raise StudyDataError("no game is being played")
        if not self.live.started:  # (see Live.started)
            raise StudyDataError("the game is starting (its first round has not begun): pause once it has")
        if self.live.paused:
            raise StudyDataError("the game is already paused")
        self._control(ev.SessionPaused(reason=reason))
        self.live.paused = True  # only once published: a pause refused here paused nothing
        self.data.append(j.GamePaused(session=self.live.session, participant=self.live.participant))

    def resume(self) -> None:
        if not self.live.paused or self.live.state != "playing":
            raise StudyDataError("the game is not paused")
        self.live.paused = False
        self._control(ev.SessionResumed())
        self.data.append(j.GameResumed(session=self.live.session, participant=self.live.participant))

    # -- the combination -----------------------------------------------------
    def combine(self, phase_id: str, timeout_s: float = 60.0) -> j.BiasCombined:
        """The bias policy of `phase_id` from its bias phase's valid games, through the combiner service."""
        phase = self.data.study.phase_by_id(phase_id)
        step = next((s for s in self.data.plan() if s.kind == "combine" and s.phase == phase_id), None)
        if step is None:
            raise StudyDataError(f"{phase_id} has no bias policy to combine")
        if step.blocked:
            raise StudyDataError(f"combining for {phase_id}: {step.blocked}")
        if step.done:  # a bias policy is made once, and again only when a game it took is marked invalid
            raise StudyDataError(f"the bias policy of {phase_id} is combined already "
                                 f"({self.data.state.combined[phase_id].output})")
        if not self._busy.acquire(blocking=False):
            raise StudyDataError("a step is already running")
        try:
            self.live = Live(phase=phase_id, state="combining")
            # people's games; scripted ones too in a rehearsal (personas asked to play: pilot, serve --pilot)
            games = self.data.combined_games(phase.bias, include_scripted=self.rehearsal or bool(self.scripted))
            if any(not g.ended.policy for g in games):  # journaled without one (a signal in its questionnaire)
                said = self.data.build_missing_policies()
                lacking = [g for g in games if not g.ended.policy]
                if lacking:  # never combined without a valid game's policy, silently
                    why = next((line for line in said if line.startswith(lacking[0].session + ":")),
                               f"{lacking[0].session}: no policy")
                    raise StudyDataError(f"combining for {phase_id}: {why}; mark the game invalid to combine "
                                         "without it")
            inputs = [g.ended.policy for g in games]
            # a new file for each combination: one made again keeps the earlier one (replay/biases.py)
            output = biases.next_output(self.data.state, phase_id)
            version = len(biases.versions(self.data.state, phase_id)) + 1  # (the bus session of each its own)
            session = f"{self.data.study.study.id}-combine-{phase_id}" + (f"-v{version}" if version > 1 else "")
            request_id = secrets.token_hex(6)
            # what a killed combination left goes; any other file at `output` is refused, never removed (it
            # removed whatever was there: a researcher's own file of that name went without a word, trial32 J)
            biasfile.remove_leftovers(self.data.folder, output, {c.output for c in self.data.state.combinations})
            biasfile.check_free(self.data.folder, output, self.data.given)
            temp = biasfile.temp_name(output, request_id)
            with journaled_or_removed(self.data.folder / temp) as line:
                return self._combine(phase_id, phase, inputs, session, request_id, (temp, output), timeout_s, line)
        finally:
            self.live.state = "idle"
            self._busy.release()

    def _combine(self, phase_id, phase, inputs: list[str], session: str, request_id: str, names: tuple[str, str],
                 timeout_s: float, line) -> j.BiasCombined:
        """`combine`'s request to the combiner service and its journal line (`line`: replay/studydata.py
        `journaled_or_removed`, which removes the bias policy if the line is not written). The combiner writes
        `names`' temporary one, put in place of its `output` with the line (services/biasfile.py)."""
        temp, output = names
        answer: list[ev.PolicyCombined] = []
        got = threading.Event()

        def on_answer(_key, payload):
            try:
                e = ev.decode_event(payload)
            except Exception:
                return
            if isinstance(e, ev.PolicyCombined) and e.request_id == request_id:
                answer.append(e)
                got.set()
        stop = threading.Event()
        bus = self.bus.scope()  # the combiner's declarations and threads go with the step (services/bus.py Bus)
        node = None
        try:
            bus.subscribe(event_key(session, "combiner", "PolicyCombined"), on_answer)
            node = Node(bus, CombinerLogic(self.data.folder), session, resume=False)
            node.start()
            node.run_in_thread(stop)
            request = stamped(ev.CombineRequested(request_id=request_id, policies=inputs, seed=self.data.study.study.seed,
                                                  output_path=temp),
                              session=session, source="experimenter", seq=1, time_ns=time.time_ns())
            bus.put(event_key(session, "experimenter", "CombineRequested"), ev.encode_event(request))
            waited = time.monotonic() + timeout_s
            while not got.wait(0.05):  # a signal does not wait for the combiner (interrupt)
                if self.interrupted is not None:
                    raise StudyDataError(f"interrupted ({getattr(self.interrupted, 'why', '')}) while combining")
                if time.monotonic() > waited:
                    raise StudyDataError(f"the combiner did not answer within {timeout_s:.0f} s")
        finally:
            stop.set()
            if node is not None:
                node.finish(shutdown_wait(self.interrupted, 2.0, reserve=0.3),
                            shutdown_wait(self.interrupted, 0.5, reserve=0.25))
            bus.close(shutdown_wait(self.interrupted, 1.0, reserve=0.2))
        result = answer[0]
        if not result.ok:
            raise StudyDataError(f"the combiner refused: {result.error}")
        policies = [read_policy(self.data.folder / p) for p in inputs]
        _, profiles = users_from_policies(policies, self.data.study.study.seed)
        event = j.BiasCombined(
            phase=phase_id, from_phase=phase.bias, request_id=request_id, inputs=inputs, users=result.users,
            output=output, actions=result.actions, decided_by=result.decided_by,
            profiles={u: {"speech": p.info.speech, "head": p.info.head, "facial": float(p.info.facial),
                          "gaze": float(p.info.gaze), "compared_states": float(p.info.compared_states)}
                      for u, p in profiles.items()},
            partial=partial_inputs(policies, inputs))
        testpause.pause("bias-written")
        with line(), biasfile.put_in_place(self.data.folder, temp, output, self.data.given):
            return self.data.append(event)

    # -- the whole protocol, for pilots and tests ----------------------------
    def run_plan(self, players: Callable[[str, str, int], object], on_step: Callable | None = None) -> list:
        """Run every open step of the plan in order; `players(pid, phase, game)` gives each game's player
        (a rehearsal: the combination takes the scripted games it played)."""
        self.rehearsal = True
        done = []
        while self.interrupted is None and (step := self.data.next_step()) is not None:
            if step.blocked:
                raise StudyDataError(f"{step.label}: {step.blocked}")
            if step.kind == "combine":
                done.append(self.combine(step.phase))
            else:
                done.append(self.run_game(step.participant, step.phase, step.game,
                                          players(step.participant, step.phase, step.game)))
            if on_step is not None:
                on_step(step, done[-1])
        return done


def bounded_reason(reason: str) -> str:
    """The experimenter's pause or abort reason, stripped; StudyDataError if over MAX_REASON characters
    (the console answers 400): it goes into an event on the bus, which must fit MAX_PAYLOAD (trial28 F20); or
    if it holds a control character (studydata.refuse_control: an abort's reason is the game's journaled end,
    written to sessions.csv and the report)."""
    refuse_control(reason, "the reason", "it")
    reason = reason.strip()
    if len(reason) > MAX_REASON:
        raise StudyDataError(f"a reason is at most {MAX_REASON:,} characters, this one has {len(reason):,}")
    return reason


ANSWER_LINES = re.compile("[\n\r\t]")  # what a questionnaire's text answer may hold of the control characters


def check_answers(items, answers) -> dict[str, str]:
    """Answers (item id -> value) checked against the items: Likert 1..scale, a choice among its options,
    text up to max_chars; required items present; nothing else. Returns them as strings."""
    if not isinstance(answers, dict):
        raise StudyDataError("answers must be an object of item id -> answer")
    known = {i.id: i for i in items}
    extra = sorted(set(answers) - set(known))
    if extra:
        raise StudyDataError(f"no question {extra[0]!r} in this questionnaire")
    out: dict[str, str] = {}
    for item in items:
        value = answers.get(item.id)
        if value is None or (isinstance(value, str) and not value.strip()):
            if item.required:
                raise StudyDataError(f"question {item.id!r} needs an answer")
            continue
        if not isinstance(value, (str, int)) or isinstance(value, bool):
            raise StudyDataError(f"question {item.id!r}: the answer must be text or a number")
        text = str(value).strip()
        # ASCII digits, and few: str.isdigit() also takes '²' (int() then raised: a 500 and a traceback), and a
        # number is bounded before it is read (a 4301-digit answer is past Python's int() limit)
        if item.kind == "likert" and not (text.isascii() and text.isdigit() and len(text) <= 9
                                          and 1 <= int(text) <= item.scale):
            raise StudyDataError(f"question {item.id!r}: a Likert answer is 1..{item.scale}")
        if item.kind == "choice" and text not in item.options:
            raise StudyDataError(f"question {item.id!r}: {text[:40]!r} is not one of its options")
        if len(text) > item.max_chars:
            raise StudyDataError(f"question {item.id!r}: at most {counted(item.max_chars, 'character')}")
        # a person's text may run over lines (a textarea), nothing else unshowable: a NUL or an ESC went raw into
        # answers.csv and the report (the rule of every free text: studydata.refuse_control)
        if (bad := unshowable(ANSWER_LINES.sub("", text))) is not None:
            raise StudyDataError(f"question {item.id!r}: the answer holds a control character ({bad.group()!r}): "
                                 "give it as text (new lines and tabs are fine)")
        out[item.id] = text
    return out


def scripted_persona(player) -> str:
    """Who plays a game as the board instead of a person: the scripted player's persona key ("scripted" for a
    player without one); "" for None, the board page a person touches."""
    if player is None:
        return ""
    persona = getattr(player, "persona", None)
    return getattr(persona, "key", "") or "scripted"


def scripted_players(runner: StudyRunner, personas: dict[str, str], press_wrong: dict[str, bool] | None = None):
    """A `players` function for run_plan: participant id -> a ScriptedPlayer of its persona."""
    from pairplay.services.scripted import ScriptedPlayer

    def make(pid: str, phase: str, game: int):
        name, items = runner.questions_for(pid, phase)
        wrong = (press_wrong or {}).get(phase, runner.data.study.study.wrong_suggestion_button)
        return ScriptedPlayer(personas[pid], press_wrong=wrong, questions=items, questionnaire=name)
    return make
