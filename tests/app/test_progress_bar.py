import io

from app.scene_cli import progress_bar


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_redraws_in_place_on_a_terminal():
    out = _Tty()
    show = progress_bar("frames", out)
    for i in range(1, 51):
        show(i, 50)
    text = out.getvalue()
    assert text.count("\r") == 50 and text.endswith("50/50 frames, 0 s, ~0 s left\n")


def test_progress_bar_writes_a_line_per_tenth_in_a_log():
    out = io.StringIO()
    show = progress_bar("trials", out)
    for i in range(1, 1301):
        show(i, 1300)
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue()
    assert len(lines) == 11  # 0 %, 10 %, …, 100 %
    assert lines[-1].startswith("[" + "#" * 30 + "] 1300/1300 trials")
