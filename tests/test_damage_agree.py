"""Every verb says the same about the same damaged recording (task "agree": a new user's damage matrix).

What a file is (whole; damaged where no event was; a whole copy of a cut file; a whole copy of a file that lost
messages) is decided in one place, reader.EventLog (`loss_free`, `source_cut`, `source_lost`), and every verb says
it in those words: recover's "complete already" line, replay --verify, rebuild, view, counterfactual (its line and
its counterfactual.md). Before, a summary zeroed at the file's end FAILed verify while view and counterfactual
said nothing; a copy of a cut file was whole to view and counterfactual; recover called a copy of a file that had
lost messages "complete already ... nothing to recover" with no word of the loss.
"""

import pytest

from pairplay.cli.main import main
from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import read_log
from pairplay.replay.recover import recover

from damageutil import small_chunked_session


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    """A real recording of a 3-round session, written by the recorder's writer in small chunks."""
    return small_chunked_session(tmp_path_factory.mktemp("agree") / "whole.mcap", "agree")


def _zeroed_summary(whole, folder):
    """The last 100 bytes zeroed (the summary's tail, the footer, the magic): every message is in the data section,
    read and checked by its CRC, so no event is lost; the file is damaged."""
    data = whole.read_bytes()
    p = folder / "foot.mcap"
    p.write_bytes(data[:-100] + b"\0" * 100)
    return p


def _recovered_cut(whole, folder):
    """A file cut at 60% (a crash), recovered: the copy is whole, its session lacks what the cut lost."""
    data = whole.read_bytes()
    cut = folder / "trunc.mcap"
    cut.write_bytes(data[:len(data) * 6 // 10])
    return recover(cut, folder / "trunc.recovered.mcap").output


def _recovered_lost(whole, folder):
    """A file whose middle chunk is overwritten (its messages lost), recovered: whole, its session is not."""
    chunks = scan(whole).chunks
    c = chunks[len(chunks) // 2]
    bad = bytearray(whole.read_bytes())
    bad[c.offset + c.length // 2:c.offset + c.length // 2 + 16] = b"\xff" * 16
    p = folder / "mid.mcap"
    p.write_bytes(bytes(bad))
    return recover(p, folder / "mid.recovered.mcap").output


KINDS = {"damaged, nothing lost": (_zeroed_summary, "loss_free"),
         "recovered from a cut": (_recovered_cut, "source_cut"),
         "recovered, messages lost": (_recovered_lost, "source_lost")}


KEY = {"loss_free": "the file is damaged, no event lost (summary: ", "source_cut": "recovered from a cut file (trunc.mcap)",
       "source_lost": "recovered from a damaged file (mid.mcap): "}  # the gist of each


def _run(capsys, *argv):
    code = main(list(argv))
    said = capsys.readouterr()
    return code, said.out + said.err


@pytest.mark.parametrize("verb", ["recover", "verify", "rebuild", "view", "counterfactual"])
@pytest.mark.parametrize("kind", list(KINDS))
def test_every_verb_says_what_the_file_is_in_the_reader_s_words(whole, tmp_path, capsys, kind, verb):
    make, words = KINDS[kind]
    p = make(whole, tmp_path)
    capsys.readouterr()
    log = read_log(p)
    said = getattr(log, words, "") or KEY[words]  # (the reader before task agree had no such words: its gist, then)
    assert KEY[words] in said, (kind, said)  # the reader says what the file is
    lost = words == "source_lost"  # events lost in the middle: verify FAILs, rebuild refuses without --partial
    if verb == "recover":
        code, out = _run(capsys, "recover", str(p), "-o", str(tmp_path / "again.mcap"))
        assert code == 0, out
        if words == "loss_free":  # not complete: a whole copy is made, the damage said as recover's own words
            assert "no message lost" in out, out
        else:  # complete already, but never "nothing to recover" without the loss (the trial: not a word of it)
            assert "complete already" in out and said in out, out
    elif verb == "verify":
        code, out = _run(capsys, "replay", str(p), "--verify")
        assert said in out, out
        last = out.strip().splitlines()[-1]
        if lost:
            assert code == 1 and last.startswith("verify: FAIL"), out
        else:  # nothing lost (or the session's end lost to a cut): PASS, the damage said with it
            assert code == 0 and last.startswith("verify: PASS"), out
        if words == "loss_free":
            assert last.endswith(f"; {said}"), last
    elif verb == "rebuild":
        code, out = _run(capsys, "rebuild", str(p), "--out", str(tmp_path / "rb"))
        assert said in out, out
        assert code == (2 if lost else 0), out
    elif verb == "view":
        code, out = _run(capsys, "view", "--recording", str(p), "--out", str(tmp_path / "v.rrd"))
        assert code == 0 and said in out, out
        saved = [line for line in out.splitlines() if line.startswith("saved ")]
        assert saved, out
        if words == "loss_free":  # drawn whole, under its own name, the damage said on stderr (cli/main.py `warn`)
            assert (tmp_path / "v.rrd").exists() and said not in saved[0] and f"pairplay view: {p}: {said}" in out, out
        else:
            assert "not whole" in out or "partial" in saved[0], out
    else:
        cf = tmp_path / "cf"
        code, out = _run(capsys, "counterfactual", str(p), "--fit-only", "--out", str(cf))
        assert code == 0 and said in out, out
        md = (cf / "counterfactual.md").read_text()
        assert said in md, md
        if words == "loss_free":
            assert "not whole" not in out and "Partial recording" not in md, out
        else:
            assert f"not whole ({said})" in out and "**Partial recording:**" in md, out


def test_view_draws_the_recording_it_read_and_checked_never_reading_it_again(whole, tmp_path):
    """Task agree (a): `view --recording trunc.mcap` once ended in a traceback inside drive(view,
    recording_items(...)) while a `recover` ran in the same folder: the file was read twice, once to check it
    (cli/view.py) and again, unchecked, inside the draw. Now the draw takes the log read and checked: a file
    removed, replaced or rewritten beside the view after its check is not read again."""
    from pairplay.services.view.sources import recording_items

    data = whole.read_bytes()
    cut = tmp_path / "trunc.mcap"
    cut.write_bytes(data[:len(data) * 6 // 10])
    held = read_log(cut)
    cut.write_bytes(b"not an MCAP file any more")  # rewritten beside the view after its check
    items = list(recording_items(cut, log=held))
    assert sum(e is not None for e, _ in items) == len(held.events) > 0
    assert [n for _, n in items if n and "not whole" in n and "truncated" in n], items[-1]
    cut.unlink()  # and gone: nothing is read
    assert sum(e is not None for e, _ in recording_items(cut, log=held)) == len(held.events)
