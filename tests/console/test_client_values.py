"""The guard's checks on their own, without a browser: its limits, a value against each widget
kind's bounds and types (``console.web.client_values.validate_value``) and the first look at any
message's fields (``check_fields``). Moved from ``test_client_guard.py``, whose tests drive a
full console over raw websockets.
"""

from __future__ import annotations

import math

import pytest

from console.web.client_guard import GuardLimits


def test_guard_limits_are_sane() -> None:
    lim = GuardLimits()
    assert lim.max_message_bytes >= 512 * 1024 + 1024  # a browser's upload part fits
    assert lim.burst >= 60 and lim.rate >= 60  # a slider drag at 60 Hz is never dropped


def test_validate_value_by_widget_kind() -> None:
    """The value check on its own, against each kind's own bounds and types."""
    import viser

    from console.web.client_values import OutOfBounds, Refused, validate_value

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        g, lim = server.gui, GuardLimits()
        count = g.add_number("n", 5, min=1, max=50, step=1)
        seven = validate_value(count, 7.0, lim)
        assert seven == 7 and isinstance(seven, int)
        for bad in (2.5, 1e308, math.nan, "7", True, None):
            with pytest.raises(Refused):
                validate_value(count, bad, lim)
        with pytest.raises(OutOfBounds):
            validate_value(count, 51, lim)
        free = g.add_number("x (m)", 0.2, step=0.001)  # no bounds of its own: the guard's
        assert validate_value(free, -0.35, lim) == -0.35
        with pytest.raises(Refused):
            validate_value(free, 1e10, lim)
        vec = g.add_vector3("p", (1.0, 2.0, 3.0), min=(0.0, 0.0, 0.0), max=(5.0, 5.0, 5.0))
        assert validate_value(vec, [1, 1, 1], lim) == (1.0, 1.0, 1.0)
        for bad in ([1, 1], [1, 1, 6], [1, 1, math.inf], "abc"):
            with pytest.raises(Refused):
                validate_value(vec, bad, lim)
        rgb = g.add_rgb("c", (1, 2, 3))
        assert validate_value(rgb, [0, 128, 255], lim) == (0, 128, 255)
        for bad in ([0, 0, 256], [0, 0, -1], [0, 0, 0.5], [0, 0]):
            with pytest.raises(Refused):
                validate_value(rgb, bad, lim)
        dd = g.add_dropdown("d", ("a", "b"))
        assert validate_value(dd, "b", lim) == "b"
        group = g.add_button_group("views", ("Top", "Side"))  # sends the pressed option's name
        assert validate_value(group, "Side", lim) == "Side"
        for bad in (True, "Front", 1):
            with pytest.raises(Refused):
                validate_value(group, bad, lim)
        with pytest.raises(Refused):
            validate_value(dd, "c", lim)
        box = g.add_checkbox("b", False)
        assert validate_value(box, True, lim) is True
        with pytest.raises(Refused):
            validate_value(box, 1, lim)
        text = g.add_text("t", "")
        assert validate_value(text, "x" * lim.max_text, lim) == "x" * lim.max_text
        with pytest.raises(Refused):
            validate_value(text, "x" * (lim.max_text + 1), lim)
        multi = g.add_multi_slider("m", min=0, max=10, step=1, initial_value=(1, 5))
        assert validate_value(multi, [2, 3], lim) == (2, 3)
        with pytest.raises(Refused):
            validate_value(multi, [2, 11], lim)
        button = g.add_button("go")
        assert validate_value(button, True, lim) is True
        with pytest.raises(Refused):
            validate_value(button, False, lim)
        with pytest.raises(Refused):
            validate_value(g.add_upload_button("u"), True, lim)
    finally:
        server.stop()


def test_check_fields_bounds_every_field_of_any_message() -> None:
    """The shape check on its own: finite moderate numbers, bounded strings and containers,
    shallow nesting, bytes only where an upload part carries them."""
    from console.web.client_values import Refused, check_fields

    lim = GuardLimits()
    fields = {"uuid": "abc", "value": [1, 2.5, None, True, {"k": "v"}], "size": lim.max_abs}
    check_fields(fields, lim, depth=0, skip_bytes=False, text_limit=lim.max_string)
    check_fields({"content": b"\x00" * 10}, lim, depth=0, skip_bytes=True,
                 text_limit=lim.max_string)
    deep: object = 1
    for _ in range(6):
        deep = [deep]
    check_fields(deep, lim, depth=0, skip_bytes=False, text_limit=lim.max_string)  # a leaf at 6
    for bad in ({"v": math.nan}, {"v": -math.inf}, {"v": lim.max_abs * 10}, {"v": 10 ** 400},
                {"v": "x" * (lim.max_string + 1)}, {"x" * (lim.max_string + 1): 1},
                {"v": list(range(lim.max_items + 1))}, {"v": b"x"}, {"v": object()}, [deep]):
        with pytest.raises(Refused):
            check_fields(bad, lim, depth=0, skip_bytes=False, text_limit=lim.max_string)
    with pytest.raises(Refused):  # a text field's own, shorter limit
        check_fields({"v": "x" * 300}, lim, depth=0, skip_bytes=False, text_limit=256)
