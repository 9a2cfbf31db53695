"""A request's hash: what strict replay matches a recorded response by."""

from agent.clients.base import ModelRequest, TextBlock

SLOW = (
    "`perceive` takes {t} s of CPU per call (median of 7 calls; slowest {u} s on seed1/start/"
    'front), over its online budget of {b} s\n- actual: `"median {t} s"`\n'
    "- metrics: calls = 7, max_s = {u}, median_s = {t}"
)


def _request(text: str) -> ModelRequest:
    return ModelRequest(
        function="perceive",
        attempt=2,
        system=(TextBlock(text="sys"),),
        content=(TextBlock(text=text),),
    )


def test_measured_timings_do_not_change_the_hash():
    a = _request(SLOW.format(t="1.674", u="1.750", b="0.6"))
    b = _request(SLOW.format(t="2.031", u="2.4", b="0.6").replace("seed1/start", "seed2/goal"))
    assert a.hash == b.hash


def test_everything_else_does():
    base = _request(SLOW.format(t="1.674", u="1.750", b="0.6"))
    assert _request(SLOW.format(t="1.674", u="1.750", b="0.5")).hash != base.hash  # the budget
    assert (
        _request(SLOW.format(t="1.674", u="1.750", b="0.6").replace("7 calls", "8 calls")).hash
        != base.hash
    )
    assert (
        _request("the plan moves 'red' by 1.674 s").hash
        != _request("the plan moves 'red' by 2.5 s").hash
    )
