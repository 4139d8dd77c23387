"""Draw a ViewModel in rerun: the board, the suggestion, the Q-table, the curves.

Rule: the drawing layer logs only what an event changed (view_model.Change),
the state at once or coalesced (RerunView), the lines and points in columns,
on three timelines: `event` (the view's event count), `round` and
`session_time` (the publisher's envelope time, so a recording replays on the
time it was made). The 24 x 88 Q-table is the costly entity (a Tensor costs
~0.45 ms, LIBRARY-NOTES), so it is rate-limited on session time: at most once
per `q_interval_s` while it changes, and always at the end of a round and of the
view, so the last table logged equals the learner's. The rate limit is on
session time, not the wall clock, so one recording always gives the same .rrd
whatever the replay speed.

Entity paths (the readback test and docs/view.md rely on them):
  board/cells      SegmentationImage 3x6 of view_model.Cell (covered/face up/matched)
  board/grid       Boxes2D outlining the 18 cards (static)
  board/faces      Boxes2D of the visible cards, labelled with their face (A..I)
  board/observed, board/match, board/candidates   Boxes2D highlights (Clear when none)
  suggestion       TextDocument: state and the suggestion's four parts in words
  q/table          Tensor (state, action), float64
  learning/reward, learning/schedule/{epsilon,alpha,psi}, learning/picks_per_round   Scalars
  session          TextDocument;  events   TextLog, one line per event
"""

from __future__ import annotations

import string
import time

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from pairplay.core.geometry import COLS, N_CARDS, ROWS, card_col, card_row

from pairplay.services.view.model import Cell, Change, ViewModel
from pairplay.numbers import counted

APP_ID = "pairplay"
FACE_LETTERS = string.ascii_uppercase
CELL_CLASSES = (  # class id, label, colour of the board image
    (Cell.COVERED, "covered", (70, 82, 105)),
    (Cell.FACE_UP, "face up", (235, 232, 215)),
    (Cell.MATCHED, "matched", (80, 165, 90)),
)
OBSERVED_COLOUR, MATCH_COLOUR, CANDIDATE_COLOUR = (40, 140, 255), (255, 140, 0), (255, 220, 0)
Q_RANGE = (-3.0, 2.0)  # Q lies between the worst reward (-3) and the best (+1 + 1/1)


def blueprint() -> rrb.Blueprint:
    """Board and suggestion on the left; Q-table, curves and the event log on the right."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(name="Board", origin="board",
                                  visual_bounds=rrb.VisualBounds2D(x_range=(-0.1, COLS + 0.1), y_range=(-0.1, ROWS + 0.1))),
                rrb.TextDocumentView(name="Suggestion", origin="suggestion"),
                rrb.TextDocumentView(name="Session", origin="session"),
                row_shares=[4, 4, 1],
            ),
            rrb.Vertical(
                rrb.TensorView(name="Q-table (state x action)", origin="q/table",
                               slice_selection=rrb.TensorSliceSelection(width=1, height=0),  # dims: 0 state, 1 action
                               scalar_mapping=rrb.TensorScalarMapping(colormap="viridis"), view_fit="fill"),
                rrb.Horizontal(
                    rrb.TimeSeriesView(name="Reward", origin="learning/reward"),
                    rrb.TimeSeriesView(name="epsilon, alpha, psi", origin="learning/schedule"),
                    rrb.TimeSeriesView(name="Picks per round", origin="learning/picks_per_round"),
                ),
                rrb.TextLogView(name="Events", origin="events"),
                row_shares=[4, 3, 2],
            ),
            column_shares=[2, 3],
        ),
        rrb.TimePanel(state="collapsed"),
        collapse_panels=True,
    )


def _centre(card: int) -> tuple[float, float]:
    """Image coordinates of a card's centre: x = column, y = row, pixel (c, r) spans [c, c+1]."""
    return card_col(card) + 0.5, card_row(card) + 0.5


def _boxes(mask: int, colour, *, half: float, radius: float, label: str | None = None) -> rr.Boxes2D:
    cards = [c for c in range(N_CARDS) if mask >> c & 1]
    return rr.Boxes2D(centers=[_centre(c) for c in cards], half_sizes=[(half, half)] * len(cards),
                      colors=[colour] * len(cards), radii=radius,
                      labels=[label] * len(cards) if label else None)


class QThrottle:
    """Log the Q-table at most once per interval of session time while it changes."""

    def __init__(self, interval_ns: int):
        self.interval_ns = interval_ns
        self.last_ns: int | None = None
        self.dirty = False

    def due(self, now_ns: int, force: bool) -> bool:
        if not self.dirty:
            return False
        return force or self.last_ns is None or now_ns - self.last_ns >= self.interval_ns

    def logged(self, now_ns: int) -> None:
        self.last_ns, self.dirty = now_ns, False


_FORCE_Q = frozenset({Change.ROUND_END, Change.SESSION})  # the Q-table is logged at these, due or not
_STATE = frozenset({Change.BOARD, Change.HIGHLIGHT, Change.SUGGESTION, Change.SESSION})
ROWS_MAX, ROWS_INTERVAL_S = 1024, 0.1  # event-log lines and curve points wait at most this many / this long


class Rows:
    """Rows of one entity waiting to be sent in columns (`rr.send_columns`): each row its own
    event / round / session_time index, so batching changes no row of the file, only the calls."""

    def __init__(self, path: str):
        self.path = path
        self.index: list[tuple[int, int, int]] = []  # (event, round or -1, session_time ns or 0)
        self.values: list = []

    def add(self, index: tuple[int, int, int], value) -> None:
        self.index.append(index)
        self.values.append(value)

    def send(self, rec: rr.RecordingStream, columns) -> None:
        """Send the rows, one call per run of rows with the same timelines (a row before the first
        round has no `round`, an unstamped event no `session_time`), then forget them."""
        if not self.index:
            return
        index = np.array(self.index, dtype=np.int64)  # (n, 3): event, round, session_time
        kind = (index[:, 1] >= 0) * 2 + (index[:, 2] != 0)
        starts = [0, *(np.flatnonzero(np.diff(kind)) + 1).tolist(), len(index)]
        for start, end in zip(starts, starts[1:]):
            run = index[start:end]
            indexes = [rr.TimeColumn("event", sequence=run[:, 0])]
            if run[0, 1] >= 0:
                indexes.append(rr.TimeColumn("round", sequence=run[:, 1]))
            if run[0, 2]:
                indexes.append(rr.TimeColumn("session_time", timestamp=run[:, 2].astype("datetime64[ns]")))
            rec.send_columns(self.path, indexes=indexes, columns=columns(self.values[start:end]))
        self.index, self.values = [], []


def _stamp(time_ns) -> int:
    """An envelope time as a timeline value: 0 (unstamped) unless an int64 that is not NaT (INT64_MIN):
    one hostile stamp must not make rerun refuse a whole batch of rows."""
    return time_ns if isinstance(time_ns, int) and -2**63 < time_ns < 2**63 else 0


def _round(value) -> int:
    """A round as a timeline value: -1 (no round timeline) unless 0 <= round < 2**63."""
    return value if isinstance(value, int) and 0 <= value < 2**63 else -1


class RerunView:
    """Fold events into a ViewModel and log what changed to a RecordingStream.

    The event log's lines and the curves' points are kept, every one with its own event / round /
    session_time, and sent in columns (`rr.send_columns`: one call per entity instead of one per
    row) at most ROWS_INTERVAL_S (wall clock) or ROWS_MAX rows apart, when the source is idle, at
    a note and at the end. `draw_interval_s` 0 draws the state (board, highlights, suggestion,
    session, Q-table) every event that changes it, as it is folded (a recording: the file holds the
    board after every event). Above 0 (the live view) it coalesces: every event is folded at once,
    but the state is drawn at most once per `draw_interval_s` of the wall clock (`clock`), as it is
    then. `idle()` (the source has nothing waiting) and `close()` draw what is pending."""

    def __init__(self, rec: rr.RecordingStream, *, q_interval_s: float = 0.25, draw_interval_s: float = 0.0,
                 clock=time.monotonic):
        self.rec = rec
        self.model = ViewModel()
        self.q_throttle = QThrottle(int(q_interval_s * 1e9))
        self.q_logged = 0
        self.draws = 0  # state drawings (coalesced: far fewer than events)
        self.draw_interval_s = draw_interval_s
        self._clock = clock
        self._last_draw = self._rows_sent = clock()
        self._pending: set[Change] = set()
        self._force_q = False
        self._now_ns = 0
        self._stamp_ns = 0  # the last event's envelope time (0: none stamped yet)
        self._shown: dict[str, int] = {}  # highlight entity -> card mask last logged
        self._lines = Rows("events")
        self._scalars = {name: Rows(name) for name in (
            "learning/reward", "learning/picks_per_round",
            *(f"learning/schedule/{n}" for n in ("epsilon", "alpha", "psi")))}
        rec.log("board", rr.AnnotationContext([(int(i), label, colour) for i, label, colour in CELL_CLASSES]),
                static=True)
        rec.log("board/grid", rr.Boxes2D(centers=[_centre(c) for c in range(N_CARDS)],
                                         half_sizes=[(0.5, 0.5)] * N_CARDS, colors=[(25, 28, 35)] * N_CARDS,
                                         radii=0.015), static=True)
        rec.log("board/cells", rr.SegmentationImage(self.model.cells()))  # before any event: all covered

    @property
    def coalescing(self) -> bool:
        return self.draw_interval_s > 0

    def handle(self, event) -> None:
        """Fold one event and log what it changed (now, or at the next draw when coalescing)."""
        changes, note = self.model.apply(event)
        m = self.model
        stamp = _stamp(event.time_ns)
        self._now_ns = stamp or self._now_ns + 1_000_000  # unstamped events: 1 ms apart
        self._stamp_ns = stamp or self._stamp_ns
        if Change.Q in changes:
            self.q_throttle.dirty = True
        force_q = bool(changes & _FORCE_Q)
        index = (m.events, _round(m.round), stamp)
        self._add_points(changes, index)
        if note:
            self._lines.add(index, (note, rr.TextLogLevel.INFO))
        if not self.coalescing:
            self._draw_state(changes, force_q)
            if len(self._lines.index) >= ROWS_MAX or self._clock() - self._rows_sent >= ROWS_INTERVAL_S:
                self._send_rows()
            return
        self._pending |= changes
        self._force_q |= force_q
        if self._clock() - self._last_draw >= self.draw_interval_s:
            self.draw()

    def idle(self) -> None:
        """The source has nothing waiting: draw what is pending, if the interval allows."""
        if self.coalescing and self._clock() - self._last_draw >= self.draw_interval_s:
            self.draw()
        elif not self.coalescing and self._lines.index:
            self._send_rows()

    def draw(self) -> None:
        """Coalescing: draw the state as it is now and send the waiting lines and points."""
        self._last_draw = self._clock()
        self._draw_state(self._pending, self._force_q)
        self._pending, self._force_q = set(), False
        self._send_rows()

    def note(self, text: str, level: str = rr.TextLogLevel.WARN) -> None:
        """A line in the event log from outside the fold (a malformed bus message, a gap)."""
        self._lines.add((self.model.events, _round(self.model.round), self._stamp_ns), (text, level))
        if not self.coalescing:
            self._send_rows()  # a note is rare and news: at once

    def close(self, timeout_s: float = 1e9) -> None:
        """Draw what is pending, log the Q-table if it changed since it was last logged, then flush
        (for at most `timeout_s`)."""
        if self.coalescing:
            self.draw()
        self._send_rows()
        self._maybe_log_q(force=True)
        self.rec.flush(timeout_sec=max(timeout_s, 0.0))

    def _send_rows(self) -> None:
        """The waiting event-log lines and curve points, in columns (each row its own indexes)."""
        self._rows_sent = self._clock()
        self._lines.send(self.rec, lambda v: rr.TextLog.columns(text=[t for t, _ in v], level=[lv for _, lv in v]))
        for rows in self._scalars.values():
            rows.send(self.rec, lambda v: rr.Scalars.columns(scalars=v))

    def _set_time(self) -> None:
        m = self.model
        self.rec.set_time("event", sequence=m.events)
        if _round(m.round) >= 0:
            self.rec.set_time("round", sequence=m.round)
        if self._stamp_ns:
            self.rec.set_time("session_time", timestamp=np.datetime64(self._stamp_ns, "ns"))

    def _draw_state(self, changes: set[Change], force_q: bool) -> None:
        """The board, highlights, suggestion, session text and Q-table as they are now (what `changes`
        names, and the Q-table if due), on the timelines of the last event folded."""
        m = self.model
        drawn = changes & _STATE
        q_due = self.q_throttle.due(self._now_ns, force_q)
        if not (drawn or q_due):
            return
        self._set_time()
        if drawn:
            self.draws += 1
        if Change.BOARD in changes:
            self._log_board()
        if Change.HIGHLIGHT in changes:
            self._log_highlights()
        if Change.SUGGESTION in changes:
            self.rec.log("suggestion", rr.TextDocument(m.suggestion_text(), media_type="text/markdown"))
        if Change.SESSION in changes:
            self.rec.log("session", rr.TextDocument(self._session_text(), media_type="text/markdown"))
        self._maybe_log_q(force=force_q)

    def _points(self, changes: set[Change]) -> list[tuple[str, float]]:
        """The curves' points an event's changes give: (entity, value)."""
        m = self.model
        points = []
        if Change.SCHEDULE in changes:
            points += [(f"learning/schedule/{n}", getattr(m, n)) for n in ("epsilon", "alpha", "psi")
                       if getattr(m, n) is not None]
        if Change.REWARD in changes and m.reward is not None:
            points.append(("learning/reward", m.reward))
        if Change.ROUND_END in changes:
            points.append(("learning/picks_per_round", m.picks_per_round[m.last_round_ended]))
        return points

    def _add_points(self, changes: set[Change], index: tuple[int, int, int]) -> None:
        for path, value in self._points(changes):
            self._scalars[path].add(index, float(value))

    def _maybe_log_q(self, force: bool) -> None:
        if self.q_throttle.due(self._now_ns, force):
            self.rec.log("q/table", rr.Tensor(self.model.q.copy(), dim_names=["state", "action"], value_range=Q_RANGE))
            self.q_throttle.logged(self._now_ns)
            self.q_logged += 1

    def _log_board(self) -> None:
        m = self.model
        self.rec.log("board/cells", rr.SegmentationImage(m.cells()))
        visible = [c for c in range(N_CARDS) if (m.face_up | m.matched) >> c & 1]
        labels = [FACE_LETTERS[m.faces[c]] if 0 <= m.faces[c] < len(FACE_LETTERS) else "?" for c in visible]
        self.rec.log("board/faces", rr.Boxes2D(centers=[_centre(c) for c in visible],
                                               half_sizes=[(0.42, 0.42)] * len(visible),
                                               labels=labels, colors=[(30, 30, 30)] * len(visible),
                                               show_labels=True))

    def _log_highlights(self) -> None:
        m = self.model
        # the match sits inside the observed card's frame, so both show when they are the same card
        for path, card, colour, label, half in (("board/observed", m.observed, OBSERVED_COLOUR, "observed", 0.47),
                                                ("board/match", m.match, MATCH_COLOUR, "match", 0.41)):
            mask = 1 << card if 0 <= card < N_CARDS else 0
            if self._shown.get(path) != mask:  # unchanged highlights are not logged again
                self._shown[path] = mask
                self.rec.log(path, _boxes(mask, colour, half=half, radius=0.04, label=label) if mask
                             else rr.Clear(recursive=False))
        if self._shown.get("board/candidates") != m.candidates:
            self._shown["board/candidates"] = m.candidates
            self.rec.log("board/candidates", _boxes(m.candidates, CANDIDATE_COLOUR, half=0.32, radius=0.025)
                         if m.candidates else rr.Clear(recursive=False))

    def _session_text(self) -> str:
        m = self.model
        text = f"**{m.session}** - {m.participant}, {m.algorithm}, {counted(m.rounds, 'round')}"
        return text + (f" - ended: {m.ended}" if m.ended else "")
