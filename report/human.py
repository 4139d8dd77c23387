"""The human-world report (thesis 7.3) of a study folder: tables, figures and report.md.

Rule: `human_report(folder, out)` reads only the study folder (replay/studydata.py):
the journal says which recording is which game of which participant in which
phase, the recordings say what happened. Games marked invalid or aborted are
listed and left out of every figure and table (a game played on a bias policy made with a game marked invalid
since is counted, played honestly, and named as such with its bias policy: replay/biases.py), and so is a game whose recording
lost events (a damaged part, messages that do not decode, parts the file a recovered one was made from
lost: reader.EventLog.lost,
the loss rebuild refuses without --partial): its picks would be a part passed
off as the game; and so is a game whose recording is missing, holds no session (a 0-byte
file, what an interrupted `session --force` leaves), no whole round or no SessionEnded (a cut file: its
rounds are a part of the game) (StudyData.recording_of):
named with the reader's words, never counted valid; and so is a recording that is not
that game's (its SessionStarted's session id, participant, the plan's rounds, a scripted
game's persona against the journal: a `session --force --session <its id>` over it). So are the games scripted
personas played instead of people (a dress rehearsal: `protocol pilot`,
`serve --pilot`; the journal's GameStarted `scripted`): they are listed by
name and persona, and counted in nothing people did, unless
`include_scripted`; a folder where no person played is reported as what it
is, a rehearsal of N scripted games. A persona is named as what it is wherever a
participant is named: a `scripted` column in picks.csv and attention.csv, and
`sim:<persona> as <id>` in the bias section, never the `human:<id>` its session
ran as (StudyData.user_names). It writes:
  picks.csv                       picks per round of every valid game (18 is perfect play)
  games.png   (figure 7.3a)       phase 1: mean picks per round of game 1, game 2, ...
  phases.png  (figure 7.3b)       mean picks per round: phase 1 (its games averaged) vs phase 2 ...
  users-<phase>.png (figure 7.6)  a reuse phase: returning users (who played before) vs new users
  merged.png  (figure 7.5)        each bias policy: state code vs action code, with a reference policy if given
                                  (every one a phase had: one made with a game marked invalid since, flagged,
                                  and the one combined again in its place; replay/biases.py)
  attention.csv                   per participant and phase: suggestions, ignored (pick interval under the
                                  window, 7.1.2), wrong-suggestion presses (7.1.3), bias share (pi-reuse)
  questionnaire.csv               per item, phase and group: n, mean/median (Likert), counts (choice)
  report.md                       all of it, with the study's settings
A report written again over an earlier one (`pairplay report --force`, the console) removes the
earlier one's files of these names that it does not write (HUMAN_OUTPUTS: a figure 7.6 of a phase no
longer reported), only those its manifest (HUMAN_MANIFEST) says a report wrote; no other file is touched
(a user's `users-x.png` stays).
"""

from __future__ import annotations

import statistics
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pairplay import __version__, csvcell
from pairplay.errors import command_word
from pairplay.core.actions import ACTION_NAMES
from pairplay.core.geometry import N_STATES, STATE_NAMES
from pairplay.replay import biases
from pairplay.replay.studydata import REPORT_MANIFEST, REPORT_OUTPUTS, StudyData, StudyDataError, named
from pairplay.schemas.policy import PolicyFileError, read_policy

from pairplay.report import plots
from pairplay.report.study import markdown_table
from pairplay.numbers import counted


# pairplay.outputs.output_folder `owned`, and the manifest of the files a report wrote in its folder (the CLI's
# and the console's): defined with the study folder (replay/studydata.py), whose participant deletion removes them
HUMAN_OUTPUTS, HUMAN_MANIFEST = REPORT_OUTPUTS, REPORT_MANIFEST


@dataclass
class GameStats:
    session: str
    participant: str
    phase: str
    game: int
    returning: bool
    picks: list[int] = field(default_factory=list)  # per round
    scripted: str = ""  # the persona that played it instead of a person
    bias: str = ""  # the bias policy file it was played on (a pi-reuse game), "" for none
    bias_flawed: str = ""  # that bias policy was made with a game marked invalid since (replay/biases.py)
    suggestions: int = 0
    ignored: int = 0  # turns resolved under the ignore window
    turns: int = 0
    presses: int = 0
    from_bias: list[int] = field(default_factory=list)  # per round: suggestions chosen from the bias policy
    per_round_suggestions: list[int] = field(default_factory=list)


class StatsFold:
    """A game's stats (GameStats' counts) folded from its recording's events as they are read, a chunk's at a time
    (StudyData.recording_of: none kept, a report of many long sessions held every file whole)."""

    def __init__(self, rounds: int) -> None:
        self.rounds = rounds
        self.picks: list[int] = []
        self.from_bias, self.per_round_suggestions = [0] * rounds, [0] * rounds
        self.suggestions = self.turns = self.ignored = self.presses = 0

    def __call__(self, recorded: list) -> None:
        rounds = self.rounds
        for r in recorded:
            e = r.event
            name = type(e).__name__
            if name == "RoundEnded":
                self.picks.append(2 * e.turns)
            elif name == "SuggestionMade":
                self.suggestions += 1
                if e.round < rounds:
                    self.per_round_suggestions[e.round] += 1
                    self.from_bias[e.round] += e.chosen_by == "bias"
            elif name == "TurnResolved":
                self.turns += 1
                self.ignored += e.ignored_by_time
            elif name == "WrongSuggestionPressed":
                self.presses += 1


def game_stats(fold: StatsFold, g, returning: bool) -> GameStats:
    """The stats of game `g` from its recording's fold."""
    return GameStats(g.session, g.participant, g.phase, g.game, returning, picks=fold.picks, scripted=g.scripted,
                     suggestions=fold.suggestions, ignored=fold.ignored, turns=fold.turns, presses=fold.presses,
                     from_bias=fold.from_bias, per_round_suggestions=fold.per_round_suggestions)


def _mean_curve(curves: list[list[int]], rounds: int) -> np.ndarray:
    """Mean per round over games (rounds a game did not play are left out)."""
    out = np.full(rounds, np.nan)
    for r in range(rounds):
        vals = [c[r] for c in curves if len(c) > r]
        if vals:
            out[r] = float(np.mean(vals))
    return out


def _fmt(x: float) -> str:
    return "-" if x != x else f"{x:.1f}"


@dataclass
class HumanReport:
    out: Path
    games: list[GameStats]
    excluded: list[str]
    curves: dict[str, np.ndarray]  # label -> mean picks per round
    questionnaire: list[list[str]]
    attention: list[list[str]]
    rehearsal: bool = False  # no person played: every reported game is a scripted persona's
    scripted: list[str] = field(default_factory=list)  # the sessions scripted personas played
    # games whose recording is damaged where no event was (reader.EventLog.loss_free): reported whole, said
    read_whole: list[str] = field(default_factory=list)
    # policy files the report cites (a bias policy, the games' policies it was combined from) that cannot be read
    # now: cited from the journal, each said with why (a cut one was cited as if whole: a new user's trial)
    unreadable: list[str] = field(default_factory=list)


def human_report(folder: str | Path, out: str | Path | None = None, reference: str | Path | None = None,
                 include_scripted: bool = False) -> HumanReport:
    """Write the report of the study in `folder` to `out` (default <folder>/report); see the module rule.

    `reference`: a policy file drawn beside each bias policy (figure 7.5 compares the
    human merge with the virtual Blind+Deaf one: `pairplay study`'s merged/blind+deaf.json).
    `include_scripted`: report the scripted games with people's (by default they are left out, listed).
    Raises StudyDataError for a folder that is not a study or that has no valid game (why each was left out)."""
    data = StudyData(folder)
    study = data.study
    out = Path(out) if out else data.folder / "report"
    out.mkdir(parents=True, exist_ok=True)
    games, excluded, read_whole = [], [], []
    valid = [g for g in data.state.games.values() if g.valid_complete]
    scripted = [g for g in valid if g.scripted]
    # a folder no person played in is a rehearsal: its scripted games are what there is to report
    rehearsal = bool(valid) and len(scripted) == len(valid)
    for g in data.state.games.values():
        if not g.valid_complete:
            excluded.append(f"{g.session} ({g.invalid and 'invalid: ' + g.invalid or (g.ended.reason if g.ended else 'running')})")
            continue
        if g.scripted and not (include_scripted or rehearsal):
            excluded.append(f"{g.session} (scripted: {g.scripted})")
            continue
        rounds = study.phase_by_id(g.phase).rounds
        # missing, no session, damaged, no whole round, another game's; its stats folded as it is read
        log, fold, why = data.recording_of(g, lambda: StatsFold(rounds))
        if log is None:
            excluded.append(f"{g.session} ({why})")
            continue
        games.append(game_stats(fold, g, data.returning(g.participant, g.phase)))
        games[-1].bias, games[-1].bias_flawed = g.bias, data.bias_flaw(g)
        if log.loss_free:  # every event read: the game counts, its file's damage said (a new user's trial: no word)
            read_whole.append(f"{g.session} ({log.loss_free})")
    if not games:  # why each game was left out, the first named (a folder of games whose recordings hold no session
        # said only "no completed, valid game", naming the resolved folder: a new user's trial)
        left = (f": {counted(len(excluded), 'game')} left out, the first {excluded[0]}" if len(excluded) > 1 else
                f": {excluded[0]} left out" if excluded else "")
        raise StudyDataError(f"no completed, valid game to report on{left}", data.given)

    # picks per round, per game and phase (figures 7.3a, 7.3b, 7.6)
    with open(out / "picks.csv", "w", newline="") as f:
        w = csvcell.writer(f)
        w.writerow(["participant", "phase", "game", "returning", "round", "picks", "scripted", "bias", "bias_flawed"])
        for s in games:
            for r, p in enumerate(s.picks):
                w.writerow([s.participant, s.phase, s.game + 1, int(s.returning), r + 1, p, s.scripted, s.bias,
                            s.bias_flawed])
    curves: dict[str, np.ndarray] = {}
    sections: list[str] = []
    first = study.phase[0]
    by_game = {f"{first.id} game {k + 1}": _mean_curve([s.picks for s in games if s.phase == first.id and s.game == k],
                                                       first.rounds) for k in range(first.games)}
    by_game = {k: v for k, v in by_game.items() if not np.isnan(v).all()}
    curves.update(by_game)
    plots.human_curves(by_game, out / "games.png", f"figure 7.3a: the games of {first.id}")
    by_phase = {p.id: _mean_curve([s.picks for s in games if s.phase == p.id], p.rounds) for p in study.phase}
    by_phase = {k: v for k, v in by_phase.items() if not np.isnan(v).all()}
    curves.update({f"{k} (all games)": v for k, v in by_phase.items()})
    plots.human_curves(by_phase, out / "phases.png", "figure 7.3b: phase against phase")
    rows = [["curve", *[f"round {r + 1}" for r in range(max(len(v) for v in curves.values()))], "n games"]]
    for label, c in curves.items():
        phase_id = label.split(" ")[0]
        n = sum(1 for s in games if s.phase == phase_id and (label.endswith("(all games)") or
                                                              label == f"{phase_id} game {s.game + 1}"))
        rows.append([label, *[_fmt(x) for x in c], *[""] * (len(rows[0]) - 2 - len(c)), str(n)])
    sections += ["## Picks per round (figures 7.3a and 7.3b)", "",
                 "Mean picks per round over the valid games (18 is perfect play: every turn a match).", "",
                 markdown_table(rows), "", "![games](games.png) ![phases](phases.png)", ""]

    reuse_phases = [p for p in study.phase if p.bias]
    for p in reuse_phases:
        groups = {"returning users": [s.picks for s in games if s.phase == p.id and s.returning],
                  "new users": [s.picks for s in games if s.phase == p.id and not s.returning]}
        group_curves = {k: _mean_curve(v, p.rounds) for k, v in groups.items() if v}
        if not group_curves:
            continue
        plots.human_curves(group_curves, out / f"users-{p.id}.png", f"figure 7.6: {p.id}, returning vs new users",
                           dashed=("returning users",))
        bias = [s for s in games if s.phase == p.id]
        share = [sum(s.from_bias[r] for s in bias) / max(1, sum(s.per_round_suggestions[r] for s in bias))
                 for r in range(p.rounds)]
        rows = [["group", *[f"round {r + 1}" for r in range(p.rounds)], "n games"]]
        rows += [[k, *[_fmt(x) for x in v], str(len(groups[k]))] for k, v in group_curves.items()]
        rows.append(["suggestions from the bias policy", *[f"{100 * x:.0f}%" for x in share], str(len(bias))])
        sections += [f"## {p.id}: returning against new users (figure 7.6)", "",
                     f"Returning users played {', '.join(q.id for q in study.phase[:study.phase.index(p)])} before; "
                     "the last row is the share of suggestions pi-reuse took from the bias policy (figure 7.4's "
                     "bars). " + played_on_words(bias), "", markdown_table(rows), "", f"![users](users-{p.id}.png)", ""]

    # the merged policies (figure 7.5)
    ref = read_policy(reference) if reference else None
    panels = []
    by_policy = {g.ended.policy: g for g in data.state.games.values() if g.ended is not None and g.ended.policy}
    unreadable: list[str] = []
    for c in data.state.combinations:  # an earlier one too: games were played on it (replay/biases.py)
        phase_id = c.phase
        personas = sorted({by_policy[p].scripted for p in c.inputs if p in by_policy and by_policy[p].scripted})
        merged_path = data.folder / c.output
        for cited in (c.output, *c.inputs):
            if (data.folder / cited).is_file():
                try:
                    read_policy(data.folder / cited)
                except PolicyFileError as err:  # its text after the file's name: why
                    unreadable.append(f"{cited} ({str(err).split(': ', 1)[-1]})")
        names = data.user_names(c)  # a persona as what it is, not the `human:<id>` its session ran as
        rules: dict[str, int] = defaultdict(int)
        for r in c.decided_by:
            rules[named(r, names)] += 1
        prof_rows = [["user", "speech incompatible %", "head incompatible %", "smile", "gaze"]]
        for user, prof in c.profiles.items():
            prof_rows.append([names.get(user, user), f"{100 * prof['speech']:.1f}", f"{100 * prof['head']:.1f}",
                              "yes" if prof["facial"] else "no", "yes" if prof["gaze"] else "no"])
        state_rows = [["state", "action", "decided by"]]
        for s_, (a, rule) in enumerate(zip(c.actions, c.decided_by)):
            if s_ < N_STATES - 1:
                state_rows.append([f"{s_} {STATE_NAMES[s_]}", f"{a}: {ACTION_NAMES[a]}", named(rule, names)])
        exact = sum(1 for a in c.actions[:N_STATES - 1] if 33 <= a <= 44)
        # a phase's bias policies, each named by its file when it had more than one, a flawed one flagged
        flaw, later = biases.flaw_words(data.state, c), biases.replaced_by(data.state, c)
        several = len(biases.versions(data.state, phase_id)) > 1
        panels.append((f"{phase_id} bias ({counted(len(c.users), 'user')})" + (f", {Path(c.output).stem}" if several
                                                                              else "")
                       + (" (made with an invalid game)" if flaw else ""), np.asarray(c.actions)))
        flagged = ([f"**Made with a game marked invalid since**: {flaw.removeprefix('made with ')}"
                    + (f"; replaced by `{later.output}`" if later else "; not combined again yet")
                    + ". The games played on it are still counted: they were played honestly on the bias policy of "
                      "their time (marking them invalid has them played again on the new one).", ""] if flaw
                   else [f"Replaced by `{later.output}`.", ""] if later else [])
        # a game marked invalid is left out of the figures: said so here, or it read as counted on this policy
        on = ", ".join(g.session + (f" (marked invalid: {g.invalid})" if g.invalid else "")
                       for g in biases.played_on(data.state, c)) or "none"
        sections += [f"## The bias policy of {phase_id}" + (f", `{c.output}`" if several or flaw else "")
                     + " (algorithm 4, figure 7.5)", "", *flagged, f"Games played on it: {on}.", "",
                     f"Combined by the combiner service from {counted(len(c.inputs), 'policy file')} of "
                     f"{', '.join(names.get(u, u) for u in c.users)} "
                     f"(`{c.output}`{'' if merged_path.is_file() else ', file since removed'}"
                     f"{', its file unreadable now' if any(u.startswith(c.output + ' (') for u in unreadable) else ''}); "
                     f"{exact} of {counted(N_STATES - 1, 'state')} say the exact position (codes 33-44); rules: "
                     + "; ".join(f"{k} x{v}" for k, v in sorted(rules.items(), key=lambda kv: -kv[1])) + "."
                     + (f" **Combined from scripted games** (personas {', '.join(personas)}): a rehearsal's bias "
                        "policy, not people's." if personas else ""), "",
                     "Profiles (algorithm 3) of the users combined:", "", markdown_table(prof_rows), "",
                     *([f"**PARTIAL profile: {c.partial}**", ""] if c.partial else []),
                     "<details><summary>every state</summary>", "", markdown_table(state_rows), "", "</details>", ""]
    if panels:
        plots.human_merged(panels, None if ref is None else ("reference: " + ref.participant, np.asarray(ref.greedy)),
                           N_STATES - 1, out / "merged.png")
        sections += ["![merged](merged.png)", ""]

    # attention: ignored suggestions and wrong-suggestion presses
    att = [["participant", "phase", "games", "returning", "suggestions", "turns", "ignored turns",
            "ignored share", "wrong-suggestion presses", "presses per suggestion", "scripted"]]
    by_pp: dict[tuple[str, str], list[GameStats]] = defaultdict(list)
    for s in games:
        by_pp[(s.participant, s.phase)].append(s)
    totals: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0, 0])
    for (pid, phase_id), ss in sorted(by_pp.items(), key=lambda kv: ([p.id for p in study.phase].index(kv[0][1]), kv[0][0])):
        sug, turns = sum(s.suggestions for s in ss), sum(s.turns for s in ss)
        ign, pr = sum(s.ignored for s in ss), sum(s.presses for s in ss)
        t = totals[phase_id]
        t[0] += sug; t[1] += turns; t[2] += ign; t[3] += pr  # noqa: E702
        att.append([pid, phase_id, str(len(ss)), "yes" if ss[0].returning else "no", str(sug), str(turns), str(ign),
                    f"{100 * ign / max(1, turns):.0f}%", str(pr), f"{100 * pr / max(1, sug):.0f}%",
                    "+".join(dict.fromkeys(s.scripted for s in ss if s.scripted))])
    for phase_id, (sug, turns, ign, pr) in totals.items():
        att.append([f"all ({phase_id})", phase_id, "", "", str(sug), str(turns), str(ign),
                    f"{100 * ign / max(1, turns):.0f}%", str(pr), f"{100 * pr / max(1, sug):.0f}%", ""])
    with open(out / "attention.csv", "w", newline="") as f:
        csvcell.writer(f).writerows(att)
    sections += ["## Ignored suggestions and wrong-suggestion presses", "",
                 f"A turn whose two picks came less than {study.study.ignore_window_ms:g} ms apart ignored its "
                 "suggestion (thesis 7.1.2: no reward, no update); a press of the wrong-suggestion button gave -3 "
                 "and asked for a new suggestion (7.1.3).", "", markdown_table(att), ""]

    # questionnaires
    q_rows = questionnaire_rows(data, {s.session for s in games})
    with open(out / "questionnaire.csv", "w", newline="") as f:
        csvcell.writer(f).writerows(q_rows)
    sections += ["## Questionnaires", "",
                 "Likert items: n, mean and median (1 = the low label); choices: counts; free text: every answer, "
                 "quoted. Groups: new users and returning users (who played an earlier phase).", "",
                 markdown_table(q_rows), ""]

    kinds = sorted({g.scripted for g in scripted})
    if rehearsal:
        title = f"# {study.study.title or study.study.id}: a rehearsal of {counted(len(scripted), 'scripted game')}"
        note = [f"No person played: every game was played by a scripted persona ({', '.join(kinds)}; "
                "`protocol pilot` or `serve --pilot`). This checks the protocol, not people: its figures are "
                "the personas'.", ""]
    elif scripted and include_scripted:
        title = f"# {study.study.title or study.study.id}: the human-world report, with scripted games"
        note = [f"{len(scripted)} of these games were played by scripted personas ({', '.join(kinds)}), not people, "
                "and are pooled with people's games as asked (`--include-scripted`).", ""]
    else:
        title = f"# {study.study.title or study.study.id}: the human-world report"
        note = [f"{counted(len(scripted), 'game')} played by scripted personas ({', '.join(kinds)}) are left out of every "
                "figure and table (`pairplay report --include-scripted` pools them).", ""] if scripted else []
    on_flawed = [s for s in games if s.bias_flawed]
    head = [title, "", *note,
            f"pairplay {__version__}; study `{study.study.id}` (seed {study.study.seed}); "
            f"{counted(len({s.participant for s in games}), 'participant')}, {counted(len(games), 'valid game')}"
            + (f"; left out: {', '.join(excluded)}" if excluded else "")
            + (f"; read whole from a damaged file: {', '.join(read_whole)}" if read_whole else "")
            + (f"; **unreadable policy files, cited from the journal**: {', '.join(unreadable)}" if unreadable else "")
            + (f"; **played on a bias policy made with a game marked invalid since** (counted: played honestly; "
               f"see its section): {', '.join(s.session for s in on_flawed)}" if on_flawed else "")
            + ". Phases: "
            + "; ".join(f"{p.id}: {counted(p.games, 'game')} x {counted(p.rounds, 'round')}, {p.algorithm} ({p.preset})"
                        + (f" on the bias of {p.bias}" if p.bias else "") for p in study.phase)
            + f". Re-run: `pairplay report {command_word(data.folder)}`.", ""]
    (out / "report.md").write_text("\n".join(head + sections))
    return HumanReport(out, games, excluded, curves, q_rows, att, rehearsal=rehearsal,
                       scripted=[g.session for g in scripted], read_whole=read_whole, unreadable=unreadable)


def played_on_words(games: list[GameStats]) -> str:
    """"Played on <bias file> (N games), ..." of a reuse phase's reported games, each flawed one flagged
    (replay/biases.py): the bias policy each game used, said where the phase's figures are."""
    by_bias: dict[str, list[GameStats]] = defaultdict(list)
    for s in games:
        by_bias[s.bias].append(s)
    return "Played on: " + "; ".join(
        f"`{bias or 'no bias policy'}` ({counted(len(ss), 'game')}: {', '.join(s.session for s in ss)})"
        + (f", **{ss[0].bias_flawed}**" if ss[0].bias_flawed else "")
        for bias, ss in by_bias.items()) + "." if games else ""


def questionnaire_rows(data: StudyData, sessions: set[str]) -> list[list[str]]:
    """One row per questionnaire item, phase and group (new / returning)."""
    answers = [a for a in data.answers() if a["session"] in sessions and not a["lost"]]  # (a lost one: no answer)
    grouped: dict[tuple, list[str]] = defaultdict(list)
    for a in answers:
        grouped[(a["questionnaire"], a["item"], a["phase"], "returning" if a["returning"] else "new")].append(a["answer"])
    rows = [["questionnaire", "item", "phase", "group", "n", "summary"]]
    phases = [p.id for p in data.study.phase]
    for (qname, item_id, phase_id, group), values in sorted(
            grouped.items(), key=lambda kv: (kv[0][0], _item_order(data, kv[0][0], kv[0][1]), phases.index(kv[0][2]),
                                             kv[0][3])):
        item = next((i for i in data.study.questionnaire.get(qname, None).item if i.id == item_id), None) \
            if qname in data.study.questionnaire else None
        kind = item.kind if item else "text"
        if kind == "likert":
            nums = [int(v) for v in values if v.strip().isdigit()]
            summary = (f"mean {statistics.mean(nums):.2f}, median {statistics.median(nums):g} "
                       f"(1 = {item.low or 'low'}, {item.scale} = {item.high or 'high'})") if nums else "-"
        elif kind == "choice":
            counts: dict[str, int] = defaultdict(int)
            for v in values:
                counts[v] += 1
            summary = "; ".join(f"{k}: {v}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1]))
        else:
            texts = [v.replace("|", "/").replace("\n", " ") for v in values if v.strip()]
            summary = " / ".join(f"\"{t[:200]}\"" for t in texts) or "-"
        rows.append([qname, item_id, phase_id, group, str(len(values)), summary])
    return rows


def _item_order(data: StudyData, qname: str, item_id: str) -> int:
    q = data.study.questionnaire.get(qname)
    ids = [i.id for i in q.item] if q else []
    return ids.index(item_id) if item_id in ids else len(ids)
