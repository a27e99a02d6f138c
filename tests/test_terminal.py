"""What reaches the terminal: a verb's usage for its own mistyped options."""

import pytest

from colonbench.cli import main


@pytest.mark.parametrize("argv, usage, wrong, close", [
    (["estimate", "--lenght-mm", "60", "x.ply"], "usage: colonbench estimate", "--lenght-mm", "--length-mm"),
    (["suites", "fetch", "demo-v1", "--url", "u", "--sha256", "0", "--quit"], "usage: colonbench suites fetch",
     "--quit", "--quiet"),
    (["benchmark", "--out", "x", "--suits", "demo"], "usage: colonbench benchmark", "--suits demo", "--suites"),
])
def test_a_mistyped_option_shows_the_verbs_usage_and_the_closest_option(argv, usage, wrong, close, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2
    assert err.startswith(usage), err
    assert f"error: unrecognized arguments: {wrong} (did you mean {close}?)" in err
    with pytest.raises(SystemExit):
        main(["estimate", "--out-dir", "x"])      # other errors as before, with the verb's usage
    err = capsys.readouterr().err
    assert err.startswith("usage: colonbench estimate") and "required: files" in err
