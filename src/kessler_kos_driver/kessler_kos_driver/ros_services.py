"""The kOS services of :class:`~.node.KosDriverNode`: ``~/command`` (LEDStatus,
SoftwareID), ``~/load_trajectory``, ``~/setup_playback``, ``~/start_playback``,
``~/stop_playback``, ``~/calibrate`` and ``~/take_picture``. A part of the node (its
``kos_services`` attribute), kept apart so the node's parameters and device set-up read in
one sitting; it is handed the node's public side (:class:`ServiceNode`: the parameters
it reads and the controller's ``call()`` boundary) and keeps the one thing it remembers
between calls (``delay_return``). Each handler calls the adapter's parts through that
boundary, never the client.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Protocol

from gimbal_driver_common.joint_command import CommandError, JointLimits
from gimbal_driver_common.ros.base_node import Answer
from gimbal_msgs.srv import Calibrate

from . import load_request
from .device import KosDevice
from .device_functions import LED_NAMES
from .moves import PlaybackSettings
from .protocol import PlaybackMode


class ServiceNode(Protocol):
    """What the services use of the node (:class:`~.node.KosDriverNode`)."""

    allow_software_id_write: bool
    return_to_home_percent: float
    picture_exposure: float

    @property
    def limits(self) -> dict[str, JointLimits]:
        """The joint limits in force."""

    def serve_device(self, response: Answer, request: Callable[[KosDevice], str],
                     joints: Sequence[str] | None = None) -> Answer:
        """A request to the adapter through the controller's ``call()`` boundary: refused
        while inactive, disconnected or (with ``joints``) while those joints cannot move;
        errors become success=false."""


class KosServices:
    """The kOS service handlers of :class:`~.node.KosDriverNode`."""

    def __init__(self, node: ServiceNode) -> None:
        self.node = node
        #: from the last ~/load_trajectory, for ~/setup_playback
        self.delay_return = False

    def _serve_device(self, response: Answer, request: Callable[[KosDevice], str],
                      joints: Sequence[str] | None = None) -> Answer:
        return self.node.serve_device(response, request, joints)

    # -------------------------------------------------------------- services
    def on_command(self, request, response):
        """~/command: the kOS Get/Set messages without a dedicated interface."""
        def action(device: KosDevice) -> str:
            name = request.command.strip()
            args = [a.strip() for a in request.arguments]
            handler = {'GetLEDStatus': (0, self._get_leds), 'SetLEDStatus': (2, self._set_leds),
                       'GetSoftwareID': (0, self._get_software_id),
                       'SetSoftwareID': (1, self._set_software_id)}.get(name)
            if handler is None:
                raise CommandError(f'unknown command {name!r}; this driver has GetLEDStatus, '
                                   'SetLEDStatus MASTER SLAVE, GetSoftwareID, SetSoftwareID ID')
            count, run = handler
            if len(args) != count:
                raise CommandError(f'{name} takes {count} argument(s), got {len(args)}: {args}')
            if request.axis:
                raise CommandError(f'{name} is device-wide: axis must be 0, got {request.axis}')
            response.results = run(device, args)
            return f'{name}: ' + ', '.join(response.results)

        return self._serve_device(response, action)

    @staticmethod
    def _led_results(master: str, slave: str) -> list[str]:
        return [f'master={master}', f'slave={slave}']

    def _get_leds(self, device: KosDevice, _args: list[str]) -> list[str]:
        return self._led_results(*device.functions.led_status())

    def _set_leds(self, device: KosDevice, args: list[str]) -> list[str]:
        states = []
        by_name = {v: k for k, v in LED_NAMES.items()}
        for which, text in zip(('master', 'slave'), args, strict=True):
            value = by_name.get(text.lower(), int(text) if text.isdigit() else None)
            if value not in LED_NAMES:
                raise CommandError(f'{which} LED status {text!r} is not one of '
                                   f'{", ".join(f"{k} ({v})" for k, v in LED_NAMES.items())}')
            states.append(value)
        return self._led_results(*device.functions.set_led_status(*states))

    def _get_software_id(self, device: KosDevice, _args: list[str]) -> list[str]:
        return [f'software_id={device.functions.software_id()}']

    def _set_software_id(self, device: KosDevice, args: list[str]) -> list[str]:
        if not self.node.allow_software_id_write:
            raise CommandError('SetSoftwareID changes what the device tells every other client '
                               'about its last user; set the parameter '
                               'allow_software_id_write:=true to allow it')
        text = args[0]
        if not text.isdigit() or int(text) > 0xFF:
            raise CommandError(f'SoftwareID must be an integer 0..255, got {text!r}')
        return [f'software_id={device.functions.set_software_id(int(text))}']

    def on_load_trajectory(self, request, response):
        def action(device: KosDevice) -> str:
            start_time = load_request.start_time(request.start_time)
            settings = PlaybackSettings(
                mode=request.playback_mode, duration=request.duration,
                loop_count=request.loop_count, rapid_reverse=request.rapid_reverse,
                start_delay=request.start_delay, start_time=start_time,
                interval=request.interval,
                exposure=request.exposure, move_photos=request.move_photos,
                pre_move_photos=request.pre_move_photos,
                post_move_photos=request.post_move_photos,
                return_to_home_percent=self.node.return_to_home_percent)
            keyframes = request.keyframes
            has_keyframes = bool(keyframes.points)
            if has_keyframes == bool(request.axes):
                raise CommandError('give either keyframes (trajectory_msgs/JointTrajectory) or '
                                   'explicit Bezier axes, not both and not neither')
            if has_keyframes:
                trajectory = device.playback.load_keyframes(
                    load_request.keyframes(keyframes, self.node.limits), settings)
            else:
                trajectory = device.playback.load_segments(
                    load_request.segments(request.axes, self.node.limits), settings)
            self.delay_return = bool(request.delay_return)
            axes = ', '.join(f'{device.joint_of(a) or a}: {len(s)} segment(s)'
                             for a, s in trajectory.axes.items())
            mode = PlaybackMode(request.playback_mode).name.lower()
            when = ''
            if start_time:
                when = time.strftime('; starts at %Y-%m-%dT%H:%M:%SZ', time.gmtime(start_time))
            elif request.start_delay > 0:
                when = f'; starts {request.start_delay:g} s after ~/start_playback'
            if self.delay_return:
                when += '; delay_return: ~/setup_playback does not move the axes'
            return (f'{mode} move loaded ({axes}), duration '
                    f'{trajectory.effective_duration():.3f} s{when}; now ~/setup_playback '
                    'and ~/start_playback')

        joints = list(request.keyframes.joint_names) or [a.joint_name for a in request.axes]
        return self._serve_device(response, action, joints)

    def on_setup_playback(self, request, response):
        def action(device: KosDevice) -> str:
            device.playback.setup_playback(self.delay_return)
            if self.delay_return:
                return ('move set up without moving (delay_return); ~/start_playback returns '
                        'to the first key frame, then plays')
            return 'motors at the first key frame, move set up; call ~/start_playback'

        return self._serve_device(response, action)

    def on_start_playback(self, request, response):
        def action(device: KosDevice) -> str:
            device.playback.start_playback()
            return 'playback started; follow ~/playback_status (FullStop ends the move)'

        return self._serve_device(response, action)

    def on_stop_playback(self, request, response):
        def action(device: KosDevice) -> str:
            device.playback.stop_playback()
            return 'StopPlayback sent: motors stop, the device reports FullStop'

        return self._serve_device(response, action)

    def on_calibrate(self, request, response):
        def action(device: KosDevice) -> str:
            joint = request.joint_name
            if joint not in self.node.limits:
                raise CommandError(f'unknown joint {joint!r}; this device has '
                                   f'{list(self.node.limits)}')
            if request.action == Calibrate.Request.MARK_BEGIN:
                device.functions.mark_begin(joint)
                return (f'{joint}: begin marked here; move to the end of the travel and mark '
                        'the end')
            if request.action == Calibrate.Request.MARK_END:
                begin, end = device.functions.mark_end(joint)
                return (f'{joint}: calibrated, range {begin:.4f} .. {end:.4f} (position is '
                        'now relative to the begin mark)')
            if request.action == Calibrate.Request.RESET:
                device.functions.reset_axis(joint)
                return f'{joint}: calibration cleared, position reset to 0'
            raise CommandError(f'action {request.action} is not MARK_BEGIN (0), MARK_END (1) '
                               'or RESET (2)')

        return self._serve_device(response, action, [request.joint_name])

    def on_take_picture(self, request, response):
        def action(device: KosDevice) -> str:
            exposure = self.node.picture_exposure
            device.functions.take_picture(exposure)
            return f'picture taken (exposure {exposure:g} s)'

        return self._serve_device(response, action)
