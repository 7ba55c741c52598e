"""bench/diagnostics/spy_summary.py: own and inclusive shares per thread from py-spy's raw (collapsed stacks) format."""

from bench.diagnostics import spy_summary as ss


def test_shares_per_thread_and_the_under_filter(tmp_path):
    p = tmp_path / "spy.txt"
    p.write_text(
        "thread (0x1);main (a.py:1);f_b (b.py:3);launch (w.py:10) 6\n"
        "thread (0x1);main (a.py:1);f_b (b.py:4);sort (w.py:20) 2\n"
        "thread (0x1);main (a.py:1);setup (a.py:9) 2\n"
        "thread (0x2);worker (t.py:5);backward (r.py:7) 5\n"
        "garbage line\n")
    t = ss.read(p)
    total, own, incl = t["thread (0x1)"]
    assert total == 10
    assert own == {"launch (w.py)": 6, "sort (w.py)": 2, "setup (a.py)": 2}
    assert incl["f_b (b.py)"] == 8 and incl["main (a.py)"] == 10  # line numbers dropped: one f_b
    assert t["thread (0x2)"][0] == 5
    under = ss.read(p, under="f_b")
    assert list(under) == ["thread (0x1)"] and under["thread (0x1)"][0] == 8
    lines = ss.report(under, rows=1)
    assert lines[0] == "== thread (0x1): 8 samples"
    assert lines[2].split() == ["75.00%", "6", "launch", "(w.py)"]


def test_reads_a_gzipped_profile(tmp_path):
    import gzip

    p = tmp_path / "spy.txt.gz"
    p.write_bytes(gzip.compress(b"main (a.py:1);f (b.py:2) 3\n"))
    assert ss.read(p)["all"][0] == 3


def test_at_keeps_the_timed_line_and_whole_threads_that_never_pass_it_and_children_split_a_function(tmp_path):
    p = tmp_path / "spy.txt"
    p.write_text(
        "thread (0x1);main (h.py:54);f_b (b.py:3);load (w.py:1) 9\n"       # the warm-up (compiles): left out
        "thread (0x1);main (h.py:67);f_b (b.py:3);launch (w.py:10) 6\n"
        "thread (0x1);main (h.py:67);f_b (b.py:3);bin (r.py:5);sort (w.py:20) 3\n"
        "thread (0x1);main (h.py:67);f_b (b.py:3);bin (r.py:5) 1\n"
        "thread (0x2);worker (t.py:5);backward (r.py:7) 5\n")
    threads, kids = ss.read_children(p, at="h.py:67", children=("bin", "f_b"))
    assert threads["thread (0x1)"][0] == 10 and threads["thread (0x2)"][0] == 5
    assert kids["bin"] == (4, {"sort (w.py)": 3, "(own)": 1})
    assert kids["f_b"] == (10, {"launch (w.py)": 6, "bin (r.py)": 4})
    assert ss.read(p)["thread (0x1)"][0] == 19  # without --at, the warm-up counts too
