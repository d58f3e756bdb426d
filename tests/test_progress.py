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


def test_a_stage_label_has_one_colon_and_no_empty_bar_is_left(monkeypatch):
    """issue #37: a run's bar read "comparison of 8 controllers: :", and a 0 % bar stayed behind."""
    from vtoladapt.experiments import running

    log = _Tty()
    monkeypatch.setattr(running._Progress, "DELAY_S", 0.0)
    import vtoladapt.progress as progress_module
    real = progress_module.progress_bar
    monkeypatch.setattr(progress_module, "progress_bar", lambda **kw: real(**{**kw, "file": log}))
    progress = running._Progress(16.0, True, "paper_comparison")
    progress.set("comparison of 8 controllers")
    progress.callback()(16.0, 16.0)
    progress.close()
    text = log.getvalue()
    assert "comparison of 8 controllers: 100%" in text
    assert ": :" not in text

    quiet = _Tty()
    monkeypatch.setattr(running._Progress, "DELAY_S", 60.0)
    monkeypatch.setattr(progress_module, "progress_bar", lambda **kw: real(**{**kw, "file": quiet}))
    progress = running._Progress(16.0, True, "paper_comparison")  # renamed and closed before its delay
    progress.set("comparison of 8 controllers")
    progress.close()
    assert "0%" not in quiet.getvalue()
