"""What the command-line tests share: the one line a refused command prints."""


def one_error_line(capsys) -> str:
    """The single non-blank line a command printed to stderr, asserting it printed no traceback and no
    second line (the error convention: one line naming the file, field, value and what is allowed)."""
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    return lines[0]
