"""The resting redraw's script (``static/resting_redraw.js``, served first in viser's page by
``console.web.resting_redraw``) on Playwright's simulated clock: viser's heartbeat (an interval of
1000 ms calling one function) fires within 3 s of the last drawing server message, input or
resize and never after; GUI-only messages do not wake it; every other interval is left alone.

The page is a stand-in for viser's (its heartbeat written as built, ``()=>f()``, and a worker
that passes messages on as viser's websocket worker does); that viser's real page holds exactly
one such heartbeat is checked on the console's page in ``test_canvas_browser.py``. The expected
beats are computed here from the clock: a beat at time t draws iff t - (last busy time) <= 3 s.
"""

from __future__ import annotations

from typing import Any

import pytest

from console.web.resting_redraw import SCRIPT_PATH

pytestmark = pytest.mark.browser
REST_MS = 3_000

_PAGE = """<!doctype html><html><head><script>{script}</script><script>
window.beats = []; window.others = 0; window.halves = 0;
function invalidate() {{ window.beats.push(performance.now()); }}
window.t0 = performance.now();
setInterval(()=>invalidate(), 1000);
setInterval(function () {{ window.others += 1; }}, 1000);
setInterval(()=>invalidate2(), 500);
function invalidate2() {{ window.halves += 1; }}
const echo = new Worker(URL.createObjectURL(new Blob(
    ["onmessage = (e) => postMessage(e.data);"], {{type: "text/javascript"}})));
window.pass = (data) => new Promise((done) => {{
    echo.addEventListener("message", () => done(performance.now()), {{once: true}});
    echo.postMessage(data);
}});
</script></head><body></body></html>"""


def _beats_expected(t0: float, start: float, end: float, busy: list[float]) -> int:
    """Beats at t0 + k s in (start, end] that fire: within REST_MS of the last busy time."""
    n, k = 0, 1
    while t0 + k * 1000 <= end:
        t = t0 + k * 1000
        if t > start:
            last = max(b for b in busy if b <= t)
            n += t - last <= REST_MS
        k += 1
    return n


def test_the_heartbeat_fires_only_within_ten_seconds_of_a_drawing_message_or_input(
        page: Any) -> None:
    page.clock.install(time=0)
    page.set_content(_PAGE.format(script=SCRIPT_PATH.read_text()))
    state = page.evaluate("() => window.__restingRedraw")
    assert state["found"] == 1 and state["restAfterMs"] == REST_MS
    t0 = page.evaluate("() => window.t0")
    # From here the clock moves only when told, so a busy moment is read where it happens.
    page.clock.pause_at(1500)
    busy = [page.evaluate("() => { window.dispatchEvent(new Event('resize')); "
                          "return performance.now(); }")]
    beats = page.evaluate("() => window.beats.length")

    def run(ms: int) -> None:
        nonlocal beats
        start = page.evaluate("() => performance.now()")
        page.clock.run_for(ms)
        end = page.evaluate("() => performance.now()")
        got = page.evaluate("() => window.beats.length") - beats
        want = _beats_expected(t0, start, end, busy)
        assert got == want, f"{got} beats in ({start:.0f}, {end:.0f}] ms, expected {want}"
        beats += got

    first = beats
    run(30_000)  # 3 beats after the resize, then rest
    assert beats - first == 3
    # GUI-only messages (a readout, a notification) draw nothing in viser: still resting.
    page.evaluate("() => window.pass({type: 'message_batch', messages: ["
                  "{type: 'GuiUpdateMessage'}, {type: 'NotificationShowMessage'},"
                  "{type: 'GuiButtonMessage'}]})")
    run(15_000)
    assert beats - first == 3
    # A scene message (the arm moved) wakes it for 3 s.
    busy.append(page.evaluate("() => window.pass({type: 'message_batch', messages: ["
                              "{type: 'GuiUpdateMessage'}, {type: 'SetBoneOrientationMessage'}]})"))
    run(30_000)
    assert beats - first == 6
    # Gui3DMessage is a scene node; a message in a form it does not know counts as drawing.
    for data in ("{type: 'message_batch', messages: [{type: 'Gui3DMessage'}]}",
                 "{type: 'connected'}"):
        busy.append(page.evaluate(f"() => window.pass({data})"))
        run(30_000)
    # The operator's input (the camera) and a resize wake it as well.
    for event in ("new PointerEvent('pointerdown')", "new WheelEvent('wheel')",
                  "new KeyboardEvent('keydown', {key: 'a'})", "new Event('resize')"):
        busy.append(page.evaluate(f"() => {{ window.dispatchEvent({event}); "
                                  "return performance.now(); }"))
        run(20_000)
    state = page.evaluate("() => window.__restingRedraw")
    assert state["drawn"] == page.evaluate("() => window.beats.length")
    # Every other interval ran untouched all along: the plain function at 1000 ms as often as
    # the heartbeat was due (drawn or rested), the bare call at 500 ms twice as often (give or
    # take the beats the clock's jump to its pause fired once: due timers fire once in a jump).
    others, halves = page.evaluate("() => [window.others, window.halves]")
    assert state["rested"] > 150 and others == state["drawn"] + state["rested"]
    assert abs(halves - 2 * others) <= 2
