"""Firmware configuration of the Arduino sketch: motor driver, PWM, homing, safety, serial.

One Python description (:class:`FirmwareConfig`, :data:`STATUS_BITS`, :data:`COMMANDS`,
:data:`UNO_PINS`) is the source of the generated ``grasp_firmware.h`` the sketch includes
(pin registers, timer settings, safety limits, status bits, compile-time pin checks) and of
what the tests and the host-side parser (:func:`parse_status_line`) read back.

Hardware model (ATmega328P at 16 MHz, Arduino Uno):

* **Motor PWM**: Timer1 in fast-PWM mode 14 (TOP = ``ICR1``), no prescaler:
  ``f = 16 MHz / (ICR1 + 1)`` -- 20 kHz (above hearing) gives ``ICR1 = 799``, 801 duty levels
  (9.6 bits).  Outputs OC1A (pin 9) and OC1B (pin 10).  Driver modes:

  - ``pwm_dir``: OC1A = PWM of |torque|, a DIR pin = direction (DRV8871-style boards with a
    PWM/PHASE input, an L298N with EN = PWM and IN1/IN2 from DIR and an inverter);
  - ``in1_in2``: OC1A = IN1, OC1B = IN2; the PWM on one input, the other held low
    (drive/coast of a DRV8871, TB6612 without the PWM pin);
  - ``lap``: locked anti-phase, OC1A and its complement on OC1B, 50 % duty = zero torque,
    an enable pin (L298N ENA) switches the bridge off in the safe state.

  The duty is ``|torque| / torque_limit``: the bridge is assumed to be current-controlled (or
  calibrated) so that full duty gives the torque limit (a voltage-driven bridge gives torque
  proportional to duty only at stall; see the sketch README).

* **Control step**: Timer2 in CTC mode at the controller rate ``1 / sample_time_s`` (must be
  realisable exactly: ``16 MHz / (prescaler (OCR2A + 1))``), the step runs in its interrupt with
  interrupts re-enabled (encoder edges are not delayed); an interrupt that arrives while the
  previous step still runs counts an **overrun** (latched fault, motor off).
* **Encoder**: quadrature on INT0/INT1 (pins 2, 3: the only external interrupts of the Uno;
  checked at export and at compile time), 4 counts per line; a transition that changes both
  channels at once is an encoder fault.
* **Homing**: ``endstop`` (a switch closed at the handle's home position, e.g. fully open) or
  ``index`` (the encoder's index pulse): on the edge into the active level the count is set to
  ``home_count``; every later pass re-synchronises and checks the count (more than
  ``home_tolerance_counts`` off = encoder fault).  Until homed the motor is off.
* **Safe state** = motor off (PWM outputs disconnected and low, DIR/enable low) and a status
  bit: on overrun, saturation longer than ``saturation_timeout_ms``, an encoder fault (bad
  transition, count beyond the range by ``encoder_margin_counts``, a homing mismatch), a bad
  table (CRC of the PROGMEM tables at boot), a watchdog reset, and while the main loop has not
  run for ``loop_timeout_ms``.  The watchdog (reset mode, ``watchdog_ms``) is fed by the
  control step only while the main loop runs: a stalled loop turns the motor off at once and
  the watchdog resets the MCU; a stalled step (or interrupts off) resets it too (a reset makes
  every pin an input: give the bridge inputs pull-downs).  After a watchdog reset the status
  has ``watchdog`` and the handle is not homed.
  Faults latch until the serial command ``C``.
* **Serial** (``baud``, 8N1, lines ending in ``\\n``): see :data:`COMMANDS`; status lines
  ``S <ms> <count> <torque_uNm> <flags> <status> <overruns> <material> <thickness_um>``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

from grasprom.control import ControllerParams
from grasprom.fe import MATERIAL_NAMES

F_CPU_HZ = 16_000_000
"""CPU clock of the Uno (Hz)."""

DRIVERS = ("pwm_dir", "in1_in2", "lap")
"""Motor driver modes (see the module docstring)."""
HOMING_MODES = ("endstop", "index")
"""Homing sources."""
WATCHDOG_MS = (15, 30, 60, 120, 250, 500)
"""Watchdog timeouts the ATmega328P offers (ms, nominal)."""
_WDP = {15: 0, 30: 1, 60: 2, 120: 3, 250: 4, 500: 5}

PWM_PINS = {"A": 9, "B": 10}
"""Timer1 outputs OC1A / OC1B on the Uno (fixed by the hardware)."""
ENCODER_PINS = (2, 3)
"""INT0 / INT1 on the Uno: the encoder's A and B channels (fixed by the hardware)."""
SERIAL_PINS = (0, 1)
"""RX / TX of the serial port (not available)."""


class StatusBit(NamedTuple):
    """One bit of the firmware's status byte."""

    name: str
    bit: int
    fault: bool  # latched fault (cleared by 'C') vs state
    doc: str


STATUS_BITS: tuple[StatusBit, ...] = (
    StatusBit("not_homed", 0, False, "not homed yet: motor off"),
    StatusBit("overrun", 1, True, "a control step was still running at the next tick"),
    StatusBit("saturation", 2, True, "torque saturated longer than saturation_timeout_ms"),
    StatusBit("encoder", 3, True, "bad quadrature transition, count off range or homing check"),
    StatusBit("table", 4, True, "CRC of the PROGMEM tables does not match (flash corrupted)"),
    StatusBit("watchdog", 5, True, "the watchdog fired (its interrupt, or the reset before boot)"),
    StatusBit("motor_off", 6, False, "safe state: motor outputs off"),
)
"""Status bits of the sketch (``GF_ST_<NAME>`` in ``grasp_firmware.h``)."""

COMMANDS: tuple[tuple[str, str], ...] = (
    ("?", "identify: '# grasprom_controller <version> fe <hash> ...' and a status line"),
    ("M <mr|nh|le>", "select the material (keeps the thickness); 'OK M <name>' or 'ERR ...'"),
    ("T <um>", "select the wall thickness in um (refused outside the tables' range)"),
    ("S", "one status line now"),
    ("R <ms>", "stream a status line every <ms> ms (0 = off, 10 .. 10000)"),
    ("C", "clear latched faults; refused while the cause persists"),
    ("H", "forget the homing (motor off until the next home edge)"),
)
"""Serial commands of the sketch (one per line, ASCII, answers 'OK ...' or 'ERR ...')."""


class Pin(NamedTuple):
    """An Uno digital pin: port letter, bit, pin-change interrupt group."""

    number: int
    port: str
    bit: int
    pcint_group: int


def _uno_pins() -> dict[int, Pin]:
    pins = {n: Pin(n, "D", n, 2) for n in range(8)}
    pins.update({n: Pin(n, "B", n - 8, 0) for n in range(8, 14)})
    pins.update({n: Pin(n, "C", n - 14, 1) for n in range(14, 20)})  # A0..A5
    return pins


UNO_PINS: dict[int, Pin] = _uno_pins()
"""Digital pins 0..19 of the Uno (14..19 = A0..A5)."""


class FirmwareError(ValueError):
    """A firmware configuration the sketch cannot run (names the field)."""


@dataclass(frozen=True)
class FirmwareConfig:
    """Sketch configuration chosen at export (``grasprom export arduino --driver ...``).

    Parameters
    ----------
    driver : str
        ``"pwm_dir"`` (default), ``"in1_in2"`` or ``"lap"`` (see the module docstring).
    pwm_hz : float
        Motor PWM frequency (Hz), 16,000 .. 31,250 (above hearing, >= 9 bits); default 20,000.
    homing : str
        ``"endstop"`` (default) or ``"index"``.
    home_pin : int
        Digital pin of the end-stop switch or the index pulse (default 4).
    home_active_low : bool
        Active level of ``home_pin`` (default True: a switch to ground with the pull-up on).
    home_count : int or None
        Handle angle at the home position, encoder counts (``None``: the open end of the
        tabulated range, ``GF_N_TOP``: an end stop at the fully open handle).
    home_tolerance_counts : int
        Largest count mismatch at a later home edge before an encoder fault (default 8).
    dir_pin : int
        Direction pin of ``pwm_dir`` (default 8).
    enable_pin : int or None
        Bridge enable pin (default: 7 for ``lap``, none otherwise); low in the safe state.
    scope_pin : int or None
        Pin high while the control step runs (timing with an oscilloscope; default 12).
    warning_pin : int
        Pin lit while the tissue-warning flag is set (default 13, the LED).
    encoder_sign : int
        +1 if the raw encoder count rises while the handle closes, -1 otherwise.
    encoder_margin_counts : int
        Counts beyond the tabulated handle range before an encoder fault (default 64).
    saturation_timeout_ms : float
        Torque saturation longer than this is a fault (ms, default 500).
    loop_timeout_ms : float
        The main loop must run at least this often, or the step turns the motor off and stops
        feeding the watchdog (ms, default 20).
    watchdog_ms : int
        Watchdog timeout, one of :data:`WATCHDOG_MS` (default 30).
    status_period_ms : int
        Status stream period at boot (ms, 0 = off; default 100).
    baud : int
        Serial baud rate (default 115200).
    """

    driver: str = "pwm_dir"
    pwm_hz: float = 20_000.0
    homing: str = "endstop"
    home_pin: int = 4
    home_active_low: bool = True
    home_count: int | None = None
    home_tolerance_counts: int = 8
    dir_pin: int = 8
    enable_pin: int | None = None
    scope_pin: int | None = 12
    warning_pin: int = 13
    encoder_sign: int = 1
    encoder_margin_counts: int = 64
    saturation_timeout_ms: float = 500.0
    loop_timeout_ms: float = 20.0
    watchdog_ms: int = 30
    status_period_ms: int = 100
    baud: int = 115_200

    def __post_init__(self) -> None:
        _check_config(self)

    @property
    def pwm_top(self) -> int:
        """``ICR1``: the PWM period in timer counts minus one."""
        return int(round(F_CPU_HZ / self.pwm_hz)) - 1

    @property
    def pwm_frequency_hz(self) -> float:
        """Realised PWM frequency (Hz): ``16 MHz / (ICR1 + 1)``."""
        return F_CPU_HZ / (self.pwm_top + 1)

    @property
    def duty_levels(self) -> int:
        """Duty levels of one direction (``lap``: half the period, 50 % = zero torque)."""
        return self.pwm_top + 1 if self.driver != "lap" else (self.pwm_top + 1) // 2

    @property
    def pwm_bits(self) -> float:
        """Duty resolution (bits): log2 of the levels of one direction."""
        return math.log2(self.duty_levels)

    @property
    def enable(self) -> int | None:
        """The bridge-enable pin in use (``lap`` defaults to pin 7)."""
        if self.enable_pin is None and self.driver == "lap":
            return 7
        return self.enable_pin

    def used_pins(self) -> dict[str, int]:
        """Every pin the sketch uses, by role."""
        pins = {"encoder A": ENCODER_PINS[0], "encoder B": ENCODER_PINS[1], "PWM A": 9}
        if self.driver != "pwm_dir":
            pins["PWM B"] = 10
        else:
            pins["dir_pin"] = self.dir_pin
        if self.enable is not None:
            pins["enable_pin"] = self.enable
        pins["home_pin"] = self.home_pin
        if self.scope_pin is not None:
            pins["scope_pin"] = self.scope_pin
        pins["warning_pin"] = self.warning_pin
        return pins


def _check_config(c: FirmwareConfig) -> None:
    """Export-time checks of a :class:`FirmwareConfig` (the C header repeats the pin checks)."""
    if c.driver not in DRIVERS:
        raise FirmwareError(f"driver must be one of {', '.join(DRIVERS)}, got {c.driver!r}")
    if c.homing not in HOMING_MODES:
        raise FirmwareError(f"homing must be one of {', '.join(HOMING_MODES)}, got {c.homing!r}")
    if not (isinstance(c.pwm_hz, (int, float)) and 16_000 <= c.pwm_hz <= 31_250):
        raise FirmwareError(
            f"pwm_hz must be within 16000 .. 31250 Hz (above hearing, >= 9 bits of duty at "
            f"16 MHz), got {c.pwm_hz!r}"
        )
    if c.watchdog_ms not in WATCHDOG_MS:
        raise FirmwareError(f"watchdog_ms must be one of {WATCHDOG_MS}, got {c.watchdog_ms!r}")
    if c.encoder_sign not in (1, -1):
        raise FirmwareError(f"encoder_sign must be 1 or -1, got {c.encoder_sign!r}")
    ints = {
        "home_tolerance_counts": (c.home_tolerance_counts, 1, 10_000),
        "encoder_margin_counts": (c.encoder_margin_counts, 1, 10_000),
        "status_period_ms": (c.status_period_ms, 0, 10_000),
        "baud": (c.baud, 1200, 1_000_000),
    }
    for name, (v, lo, hi) in ints.items():
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise FirmwareError(f"{name} must be an integer in {lo} .. {hi}, got {v!r}")
    if 0 < c.status_period_ms < 10:
        raise FirmwareError(f"status_period_ms must be 0 or >= 10 ms, got {c.status_period_ms}")
    for name, v, lo, hi in (
        ("saturation_timeout_ms", c.saturation_timeout_ms, 1.0, 60_000.0),
        ("loop_timeout_ms", c.loop_timeout_ms, 1.0, 1_000.0),
    ):
        if not (isinstance(v, (int, float)) and lo <= v <= hi):
            raise FirmwareError(f"{name} must be within {lo:g} .. {hi:g} ms, got {v!r}")
    if not isinstance(c.home_active_low, bool):
        raise FirmwareError(f"home_active_low must be true or false, got {c.home_active_low!r}")
    if c.home_count is not None and (
        isinstance(c.home_count, bool) or not isinstance(c.home_count, int)
    ):
        raise FirmwareError(f"home_count must be an integer count or null, got {c.home_count!r}")
    _check_pins(c)


def _check_pins(c: FirmwareConfig) -> None:
    fixed = {9: "PWM A (OC1A)", 10: "PWM B (OC1B)", 2: "encoder A (INT0)", 3: "encoder B (INT1)"}
    free = {
        "dir_pin": c.dir_pin if c.driver == "pwm_dir" else None,
        "enable_pin": c.enable,
        "home_pin": c.home_pin,
        "scope_pin": c.scope_pin,
        "warning_pin": c.warning_pin,
    }
    seen: dict[int, str] = {}
    for name, pin in free.items():
        if pin is None:
            continue
        if isinstance(pin, bool) or not isinstance(pin, int) or pin not in UNO_PINS:
            raise FirmwareError(f"{name} must be an Uno pin 0 .. 19 (A0 = 14), got {pin!r}")
        if pin in SERIAL_PINS:
            raise FirmwareError(f"{name} = {pin} is the serial port (RX 0 / TX 1)")
        if pin in fixed and not (pin == 10 and c.driver == "pwm_dir"):
            raise FirmwareError(f"{name} = {pin} is taken by {fixed[pin]}")
        if pin == 11:
            raise FirmwareError(f"{name} = 11 is OC2A: Timer2 runs the control step")
        if pin in seen:
            raise FirmwareError(f"{name} = {pin} is already {seen[pin]}")
        seen[pin] = name


@dataclass(frozen=True)
class ControlTimer:
    """Timer2 CTC setting of the control step."""

    prescaler: int
    ocr: int
    cs_bits: int  # TCCR2B clock-select value

    @property
    def rate_hz(self) -> float:
        """Realised control rate (Hz)."""
        return F_CPU_HZ / (self.prescaler * (self.ocr + 1))


_T2_PRESCALERS = ((1, 1), (8, 2), (32, 3), (64, 4), (128, 5), (256, 6), (1024, 7))


def control_timer(sample_time_s: float) -> ControlTimer:
    """Timer2 prescaler and compare value realising ``sample_time_s`` exactly.

    Parameters
    ----------
    sample_time_s : float
        Controller period (s).

    Returns
    -------
    ControlTimer

    Raises
    ------
    FirmwareError
        When no prescaler gives the period to 1 ppm with an 8-bit compare value.
    """
    ticks = F_CPU_HZ * sample_time_s
    for presc, cs in _T2_PRESCALERS:
        n = ticks / presc
        ocr = int(round(n)) - 1
        if 1 <= ocr <= 255 and abs((ocr + 1) - n) <= 1e-6 * n:
            return ControlTimer(presc, ocr, cs)
    raise FirmwareError(
        f"sample_time_s = {sample_time_s:g} s is not a Timer2 period of the Uno (16 MHz / "
        "(prescaler 1..1024 x 1..256)); e.g. 0.001 s (1 kHz), 0.0005, 0.00025, 0.002 s"
    )


def _pin_macros(prefix: str, pin: int) -> list[str]:
    p = UNO_PINS[pin]
    return [
        f"#define {prefix} {pin}",
        f"#define {prefix}_PORT PORT{p.port}",
        f"#define {prefix}_DDR DDR{p.port}",
        f"#define {prefix}_PINREG PIN{p.port}",
        f"#define {prefix}_BIT {p.bit}",
    ]


def _duty_scaling(c: FirmwareConfig, params: ControllerParams) -> tuple[int, int, int, int]:
    """Handle force at the torque limit (mN), duty levels per direction, and the multiplier /
    shift with ``duty = |Fi mN| * mul >> shift`` (no division in the interrupt)."""
    fi_limit_mN = round(params.torque_limit_Nm / (params.pulley_radius_mm * 1e-3) * 1e3)
    levels = c.duty_levels
    shift = 30 - levels.bit_length()  # |Fi| <= Fi limit: |Fi| x mul < 2^30
    mul = round(levels * (1 << shift) / fi_limit_mN)
    if mul < 1024:
        raise FirmwareError(
            f"the handle force at the torque limit ({fi_limit_mN} mN) is too large for the "
            "duty scaling (raise the pulley radius or lower torque_limit_Nm)"
        )
    return fi_limit_mN, levels, mul, shift


def firmware_header(config: FirmwareConfig, params: ControllerParams, *, table_crc: int,
                    version: str, fe_hash: str,
                    materials: Sequence[str] = MATERIAL_NAMES) -> str:  # fmt: skip
    """C source of ``grasp_firmware.h``: the sketch's generated configuration.

    Parameters
    ----------
    config : FirmwareConfig
    params : ControllerParams
        Controller parameters of the export (sample time, torque limit).
    table_crc : int
        CRC-16/CCITT of the PROGMEM tables (:meth:`FixedTables.table_crc`).
    version, fe_hash : str
        grasprom version and the surrogate's FE hash (reported by the ``?`` command).
    materials : sequence of str
        The materials the tables cover (:attr:`FixedTables.material_names`): ``M`` refuses the
        others, naming these (``GF_MATERIAL_LIST``).

    Returns
    -------
    str
    """
    c = config
    tm = control_timer(params.sample_time_s)
    rate = tm.rate_hz

    def steps(ms: float) -> int:
        return max(1, int(math.ceil(ms * 1e-3 * rate)))

    fi_limit_mN, levels, mul, shift = _duty_scaling(c, params)
    home_count = "GF_N_TOP" if c.home_count is None else str(c.home_count)
    lines = [
        "/* Generated by grasprom.export.arduino.firmware -- do not edit (re-export instead). */",
        "#ifndef GRASP_FIRMWARE_H",
        "#define GRASP_FIRMWARE_H",
        "",
        f'#define GF_VERSION "{version}"',
        f'#define GF_FE_HASH "{fe_hash[:12]}"',
        f'#define GF_DRIVER_NAME "{c.driver}"',
        f'#define GF_HOMING_NAME "{c.homing}"',
        f"#define GF_DRIVER_{c.driver.upper()} 1",
        f"#define GF_HOMING_{c.homing.upper()} 1",
        "",
        f"/* motor PWM: Timer1 fast PWM (mode 14), {c.pwm_frequency_hz:g} Hz, "
        f"{levels} levels per direction ({c.pwm_bits:.2f} bits) */",
        f"#define GF_PWM_TOP {c.pwm_top}u",
        f"/* duty counts = |Fi mN| * GF_DUTY_MUL >> GF_DUTY_SHIFT (Fi limit {fi_limit_mN} mN = "
        f"{levels} counts) */",
        f"#define GF_DUTY_LEVELS {levels}u",
        f"#define GF_DUTY_MUL {mul}UL",
        f"#define GF_DUTY_SHIFT {shift}",
        "",
        f"/* control step: Timer2 CTC, prescaler {tm.prescaler}, OCR2A {tm.ocr}: {rate:g} Hz */",
        f"#define GF_T2_CS {tm.cs_bits}",
        f"#define GF_T2_OCR {tm.ocr}",
        f"#define GF_RATE_HZ {round(rate)}UL",
        "",
        "/* safety */",
        f"#define GF_SAT_STEPS {steps(c.saturation_timeout_ms)}u /* saturation_timeout_ms "
        f"{c.saturation_timeout_ms:g} */",
        f"#define GF_LOOP_STEPS {steps(c.loop_timeout_ms)}u /* loop_timeout_ms "
        f"{c.loop_timeout_ms:g} */",
        f"#define GF_WDP {_WDP[c.watchdog_ms]} /* watchdog {c.watchdog_ms} ms */",
        f"#define GF_ENC_MARGIN {c.encoder_margin_counts}L",
        f"#define GF_HOME_TOL {c.home_tolerance_counts}L",
        f"#define GF_HOME_COUNT ((int32_t){home_count})",
        f"#define GF_HOME_ACTIVE_LOW {int(c.home_active_low)}",
        f"#define GF_ENCODER_SIGN ({c.encoder_sign})",
        f"#define GF_TABLE_CRC 0x{table_crc:04X}u",
        f"#define GF_STATUS_PERIOD_MS {c.status_period_ms}u",
        f"#define GF_BAUD {c.baud}UL",
        *_material_lines(params, materials),
        f'#define GF_COMMAND_LIST "{" ".join(cmd.split()[0] for cmd, _ in COMMANDS)}"',
        "",
    ]
    lines += _status_lines() + ["", "/* pins */"]
    lines += _pin_lines(c)
    lines += ["", "#endif", ""]
    return "\n".join(lines)


def _material_lines(params: ControllerParams, materials: Sequence[str]) -> list[str]:
    """The boot case and the material names of ``grasp_firmware.h``: names by code (the index
    of ``gf_init``), the covered ones in ``GF_MATERIAL_LIST``."""
    return [
        f"#define GF_BOOT_MATERIAL {MATERIAL_NAMES.index(params.material)} /* {params.material} */",
        f"#define GF_BOOT_THICKNESS_UM {round(params.thickness_mm * 1000)}",
        "/* material names by code (gf_init's index); the tables cover GF_MATERIAL_LIST */",
        "#define GF_MATERIAL_NAMES {" + ", ".join(f'"{m}"' for m in MATERIAL_NAMES) + "}",
        f"#define GF_MATERIAL_NAME_LEN {max(len(m) for m in MATERIAL_NAMES) + 1}",
        f'#define GF_MATERIAL_LIST "{", ".join(m for m in MATERIAL_NAMES if m in materials)}"',
    ]


def _status_lines() -> list[str]:
    """``GF_ST_*`` status bits of :data:`STATUS_BITS` and the mask of the latched faults."""
    lines = ["/* status bits (grasprom.export.arduino.firmware.STATUS_BITS) */"]
    for s in STATUS_BITS:
        lines.append(f"#define GF_ST_{s.name.upper()} 0x{1 << s.bit:02X}u /* {s.doc} */")
    faults = sum(1 << s.bit for s in STATUS_BITS if s.fault)
    return [*lines, f"#define GF_ST_FAULTS 0x{faults:02X}u"]


def _pin_lines(c: FirmwareConfig) -> list[str]:
    """Pin macros of ``grasp_firmware.h`` and their compile-time checks."""
    ph = UNO_PINS[c.home_pin]
    lines: list[str] = []
    lines += ["#define GF_PIN_ENC_A 2", "#define GF_PIN_ENC_B 3"]
    lines += _pin_macros("GF_PIN_PWM_A", 9)
    if c.driver != "pwm_dir":
        lines += _pin_macros("GF_PIN_PWM_B", 10)
    if c.driver == "pwm_dir":
        lines += _pin_macros("GF_PIN_DIR", c.dir_pin)
    if c.enable is not None:
        lines += _pin_macros("GF_PIN_EN", c.enable)
    if c.scope_pin is not None:
        lines += _pin_macros("GF_PIN_SCOPE", c.scope_pin)
    lines += _pin_macros("GF_PIN_WARN", c.warning_pin)
    lines += _pin_macros("GF_PIN_HOME", c.home_pin)
    lines += [
        f"#define GF_HOME_PCMSK PCMSK{ph.pcint_group}",
        f"#define GF_HOME_PCIE PCIE{ph.pcint_group}",
        f"#define GF_HOME_VECT PCINT{ph.pcint_group}_vect",
        "",
        "/* compile-time pin checks (repeat the export's; edit the export, not this file) */",
        "#if GF_PIN_ENC_A != 2 || GF_PIN_ENC_B != 3",
        '#error "the encoder must be on pins 2 and 3 (INT0/INT1, the Uno\'s external interrupts)"',
        "#endif",
    ]
    roles = ("DIR", "EN", "SCOPE", "WARN", "HOME")
    for r in roles:
        pwm_b = f" || GF_PIN_{r} == 10" if c.driver != "pwm_dir" else ""
        lines += [
            f"#ifdef GF_PIN_{r}",
            f"#if GF_PIN_{r} <= 3 || GF_PIN_{r} == 9 || GF_PIN_{r} == 11 || GF_PIN_{r} > 19"
            + pwm_b,
            f'#error "GF_PIN_{r}: pins 0-3, 9-11 are serial, encoder, PWM or Timer2"',
            "#endif",
            "#endif",
        ]
    for i, a in enumerate(roles):
        for b in roles[i + 1 :]:
            lines += [
                f"#if defined(GF_PIN_{a}) && defined(GF_PIN_{b})",
                f"#if GF_PIN_{a} == GF_PIN_{b}",
                f'#error "GF_PIN_{a} and GF_PIN_{b} are the same pin"',
                "#endif",
                "#endif",
            ]
    return lines


class StatusLine(NamedTuple):
    """A parsed status line of the sketch (``S ...``)."""

    ms: int
    count: int
    torque_uNm: int
    flags: int
    status: int
    overruns: int
    material: str
    thickness_um: int

    def has(self, name: str) -> bool:
        """Whether the status bit ``name`` (:data:`STATUS_BITS`) is set."""
        bit = {s.name: s.bit for s in STATUS_BITS}[name]
        return bool(self.status >> bit & 1)


def parse_status_line(line: str) -> StatusLine | None:
    """Parse one ``S ...`` line of the sketch's serial output (``None`` for other lines)."""
    parts = line.strip().split()
    if len(parts) != 9 or parts[0] != "S":
        return None
    try:
        return StatusLine(
            int(parts[1]),
            int(parts[2]),
            int(parts[3]),
            int(parts[4], 16),
            int(parts[5], 16),
            int(parts[6]),
            parts[7],
            int(parts[8]),
        )
    except ValueError:
        return None
