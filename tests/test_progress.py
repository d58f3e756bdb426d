"""The shared progress bar: calm in a log file, live on a terminal."""
import io

from vtoladapt.progress import NON_TTY_MININTERVAL_S, progress_bar


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_a_log_file_gets_few_redraws():
    log = io.StringIO()
    bar = progress_bar(total=1000, file=log, desc="x")
    assert bar.mininterval == NON_TTY_MININTERVAL_S
    for _ in range(1000):
        bar.update(1)
    bar.close()
    # the first draw and the final one; every update in between fell inside the 30 s interval
    assert log.getvalue().count("\r") <= 3
    assert "1000/1000" in log.getvalue()


def test_a_terminal_keeps_tqdm_default_rate():
    bar = progress_bar(total=10, file=_Tty(), desc="x")
    assert bar.mininterval < 1.0
    bar.close()
