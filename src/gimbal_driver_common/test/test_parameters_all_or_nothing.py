"""A parameter set is all or nothing on the device (no node: the sending rule alone).

The rclpy callback path over the same rule is in test_parameters_unit.py.
"""

from __future__ import annotations

from gimbal_driver_common.ros.parameters import DeviceChange, send_all_or_nothing


class Device:
    """Holds named values; refuses the values in ``refused``; logs every send in order."""

    def __init__(self, **held: object) -> None:
        self.held = dict(held)
        self.log: list[tuple[str, object]] = []
        self.refused: set[tuple[str, object]] = set()

    def sender(self, name: str):
        def send(value: object) -> None:
            self.log.append((name, value))
            if (name, value) in self.refused:
                raise RuntimeError(f'NACK {name}')
            self.held[name] = value
        return send

    def change(self, name: str, value: object) -> DeviceChange:
        return DeviceChange(name, self.sender(name), value, self.held[name])


def test_a_set_the_device_takes_whole_is_sent_in_order() -> None:
    device = Device(first=1, second=2)
    assert send_all_or_nothing([device.change('first', 10), device.change('second', 20)]) is None
    assert device.log == [('first', 10), ('second', 20)]
    assert device.held == {'first': 10, 'second': 20}


def test_the_second_refused_puts_the_first_back() -> None:
    device = Device(first=1, second=2)
    device.refused.add(('second', 20))
    reason = send_all_or_nothing([device.change('first', 10), device.change('second', 20)])
    assert reason == "parameter 'second': the device refused 20: NACK second"
    assert device.log == [('first', 10), ('second', 20), ('first', 1)]
    assert device.held == {'first': 1, 'second': 2}


def test_values_taken_are_put_back_in_reverse_order() -> None:
    device = Device(a=1, b=2, c=3)
    device.refused.add(('c', 30))
    reason = send_all_or_nothing([device.change('a', 10), device.change('b', 20),
                                  device.change('c', 30)])
    assert reason is not None and "'c'" in reason
    assert device.log[3:] == [('b', 2), ('a', 1)]
    assert device.held == {'a': 1, 'b': 2, 'c': 3}


def test_the_first_refused_sends_nothing_more() -> None:
    device = Device(first=1, second=2)
    device.refused.add(('first', 10))
    reason = send_all_or_nothing([device.change('first', 10), device.change('second', 20)])
    assert reason is not None and "'first'" in reason
    assert device.log == [('first', 10)]
    assert device.held == {'first': 1, 'second': 2}


def test_a_value_that_cannot_be_put_back_is_named_in_the_reason() -> None:
    device = Device(first=1, second=2)
    device.refused.update({('second', 20), ('first', 1)})
    reason = send_all_or_nothing([device.change('first', 10), device.change('second', 20)])
    assert reason is not None
    assert reason.startswith("parameter 'second': the device refused 20")
    assert "'first' may still hold 10 (putting back 1 failed: NACK first)" in reason
    assert device.held == {'first': 10, 'second': 2}
