"""The Arduino firmware (issue 17) on a simulated bench: the sketch built with arduino-mk, run
under simavr with a harness driving the encoder, the home input and the serial port.

Checked from the outside, as on a bench: the PWM frequency and duty from the Timer1 registers
(against the Python reference's handle force), the control interrupt's rate from the scope pin,
the watchdog on a stalled loop and with interrupts off, homing, serial commands changing the
case, and the safe state on overrun, saturation, encoder faults and a corrupted table.  CI
installs gcc-avr, avr-libc, simavr, libsimavr-dev, arduino-mk, arduino-builder: with
``CI=true`` a missing tool fails, never skips.
"""

from __future__ import annotations

import dataclasses
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from grasprom.control import ControllerParams
from grasprom.export import arduino as ar
from grasprom.export.arduino import simbench as sb
from tests.export.test_arduino import need_simavr
from tests.tools import CI, need

WGM_MODE14 = (0x02, 0x18)  # WGM11 in TCCR1A; WGM13 | WGM12 in TCCR1B
COM1A1, COM1B1, COM1B0 = 0x80, 0x20, 0x10


def need_bench() -> None:
    need("make", "make")
    need("avr-gcc", "gcc-avr avr-libc")
    need_simavr()
    if not Path("/usr/share/arduino/Arduino.mk").exists():
        msg = "arduino-mk missing: apt-get install arduino-mk arduino-core-avr"
        (pytest.fail if CI else pytest.skip)(msg)


def header_constants(sketch_dir: Path) -> dict[str, int]:
    """Integer #defines of the generated headers (GF_N_TOP, GF_PWM_TOP, ...)."""
    out = {}
    for name in ("grasp_fixed_config.h", "grasp_firmware.h"):
        for m in re.finditer(
            r"#define (GF_\w+) \(?(-?\d+)[uUL]*\)?", (sketch_dir / name).read_text()
        ):
            out[m.group(1)] = int(m.group(2))
    return out


@dataclasses.dataclass
class Built:
    params: ControllerParams
    config: ar.FirmwareConfig
    sketch: Path
    elf: Path
    k: dict[str, int]

    def raw_for(self, count: int) -> int:
        """Raw encoder count that puts the handle at ``count`` after homing at raw 0."""
        return self.k["GF_N_TOP"] - count

    def run(self, script: sb.BenchScript, end_ms: float, tmp: Path) -> sb.BenchRun:
        return sb.run_bench(self.elf, script, end_ms, tmp, self.config)


def copy_sketch(b: Built, tmp: Path) -> Path:
    """A fresh copy of an exported sketch folder (without its build output)."""
    sk = tmp / "grasprom_controller"
    shutil.copytree(b.sketch, sk, ignore=shutil.ignore_patterns("build-*"))
    return sk


def build(surrogate, tmp: Path, params=None, **fw) -> Built:
    need_bench()
    p = params or ControllerParams()
    cfg = ar.FirmwareConfig(**fw)
    res = ar.export_arduino(tmp, surrogate=surrogate, params=p, measure=False, firmware=cfg)
    elf = sb.build_sketch(res.sketch_dir, test_hooks=True)
    return Built(p, cfg, res.sketch_dir, elf, header_constants(res.sketch_dir))


@pytest.fixture(scope="module")
def fw(surrogate, tmp_path_factory):
    """The default firmware (PWM + DIR, end-stop homing, 1 kHz) built with the test hooks."""
    return build(surrogate, tmp_path_factory.mktemp("fw"))


def homed_script() -> sb.BenchScript:
    """Switch open at boot, the end stop pressed at 20 ms (handle open, raw count 0)."""
    return sb.BenchScript().pin(4, 1, 0).home(20).encoder(22, 0)


def handle_force_N(params: ControllerParams, torque_uNm: int) -> float:
    return torque_uNm * 1e-6 / (params.pulley_radius_mm * 1e-3)


# ------------------------------------------------------------------------- configuration


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("driver", "h_bridge", "driver must be one of"),
        ("homing", "none", "homing must be one of"),
        ("pwm_hz", 490.0, "pwm_hz must be within"),
        ("pwm_hz", 40_000.0, "pwm_hz must be within"),
        ("watchdog_ms", 20, "watchdog_ms must be one of"),
        ("home_pin", 2, "taken by encoder A"),
        ("home_pin", 9, "taken by PWM A"),
        ("home_pin", 0, "serial port"),
        ("home_pin", 11, "OC2A"),
        ("home_pin", 25, "must be an Uno pin"),
        ("dir_pin", 12, "scope_pin = 12 is already dir_pin"),
        ("encoder_sign", 0, "encoder_sign must be 1 or -1"),
        ("status_period_ms", 5, "0 or >= 10 ms"),
        ("saturation_timeout_ms", 0.0, "saturation_timeout_ms must be within"),
        ("home_count", 1.5, "home_count must be an integer"),
    ],
)
def test_firmware_config_refuses_what_the_board_cannot_do(field, value, match):
    with pytest.raises(ar.FirmwareError, match=match):
        ar.FirmwareConfig(**{field: value})


def test_in1_in2_and_lap_use_pin_10():
    with pytest.raises(ar.FirmwareError, match="taken by PWM B"):
        ar.FirmwareConfig(driver="in1_in2", home_pin=10)
    assert ar.FirmwareConfig(driver="pwm_dir", home_pin=10).home_pin == 10
    assert ar.FirmwareConfig(driver="lap").enable == 7


@pytest.mark.parametrize(
    ("t_s", "presc", "ocr"), [(1e-3, 64, 249), (5e-4, 32, 249), (2.5e-4, 32, 124), (2e-3, 128, 249)]
)
def test_control_timer_realises_the_sample_time_exactly(t_s, presc, ocr):
    tm = ar.control_timer(t_s)
    assert (tm.prescaler, tm.ocr) == (presc, ocr)
    assert tm.rate_hz == pytest.approx(1.0 / t_s, rel=1e-12)


def test_control_timer_refuses_an_unrealisable_rate(surrogate, tmp_path):
    with pytest.raises(ar.FirmwareError, match="not a Timer2 period"):
        ar.control_timer(1 / 3000)
    p = ControllerParams(sample_time_s=1 / 3000)
    with pytest.raises(ar.FirmwareError, match="not a Timer2 period"):
        ar.export_arduino(tmp_path / "x", surrogate=surrogate, params=p, measure=False)
    assert not (tmp_path / "x").exists()  # nothing written


def test_pwm_resolution_and_frequency():
    c = ar.FirmwareConfig()
    assert c.pwm_top == 799 and 16e6 / (c.pwm_top + 1) == 20_000
    assert c.pwm_bits >= 9
    assert ar.FirmwareConfig(driver="lap").pwm_bits == pytest.approx(np.log2(400))


# -------------------------------------------------------------------------- table CRC


def test_crc16_ccitt_check_value():
    """The published check value of CRC-16/CCITT-FALSE (Greg Cook's CRC catalogue)."""
    assert ar.crc16_ccitt(b"123456789") == 0x29B1


@pytest.mark.parametrize("which", ["surrogate", "surrogate_mr_le"])
def test_table_crc_of_python_matches_the_core(request, which, tmp_path):
    """Also for tables that leave a material out (issue 16: its empty entry adds nothing)."""
    need("gcc", "gcc")
    t = ar.build_tables(request.getfixturevalue(which), ControllerParams(), 0.005)
    ar.write_core(t, tmp_path)
    (tmp_path / "crc_main.c").write_text(
        '#include <stdio.h>\n#include "grasp_core.h"\n'
        'int main(void) { printf("%u\\n", (unsigned)gf_table_crc()); return 0; }\n'
    )
    exe = tmp_path / "crc"
    subprocess.run(
        [
            "gcc",
            "-std=c99",
            "-Wall",
            "-Werror",
            "-o",
            str(exe),
            str(tmp_path / "grasp_core.c"),
            str(tmp_path / "crc_main.c"),
            "-lm",
        ],
        check=True,
    )
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    assert int(out) == t.table_crc()


# ------------------------------------------------------------------------ on the bench


def test_sketch_fits_the_uno_and_says_what_it_is(fw, tmp_path):
    res = subprocess.run(
        ["avr-size", "-A", str(fw.elf)], capture_output=True, text=True, check=True
    )
    sec = {
        p[0]: int(p[1])
        for p in (ln.split() for ln in res.stdout.splitlines())
        if len(p) >= 2 and p[1].isdigit()
    }
    flash, ram = sec[".text"] + sec[".data"], sec[".data"] + sec[".bss"]
    print(f"\nsketch: flash {flash} B of 32,256, static RAM {ram} B of 2,048")
    assert flash <= 32_256 and ram <= 1_024
    run = fw.run(sb.BenchScript().send(30, "?"), 60, tmp_path)
    ident = [s for _, s in run.lines if s.startswith("# grasprom_controller")]
    assert ident and "driver pwm_dir" in ident[0] and "rate 1000 Hz" in ident[0]
    assert "pwm 20000 Hz" in ident[0]
    assert any(s.startswith("BOOT reset") for _, s in run.lines)


def test_pwm_registers_and_duty_follow_the_rendered_force(fw, surrogate, tmp_path):
    """Timer1 in fast PWM mode 14 at 20 kHz without prescaler; the duty (OCR1A + 1) / (ICR1 + 1)
    is |handle force| / force at the torque limit of the Python reference, within one level."""
    k = fw.k
    hold = k["GF_N_LO"] + (k["GF_N_CONTACT"] - k["GF_N_LO"]) // 4  # jaws on the tissue
    script = homed_script().encoder(200, fw.raw_for(hold)).send(400, "S")
    run = fw.run(script, 420, tmp_path)
    r = run.at(398)
    assert (r.TCCR1A & 0x03, r.TCCR1B & 0x18) == WGM_MODE14 and r.TCCR1B & 0x07 == 1
    f_pwm = 16e6 / (r.ICR1 + 1)
    assert f_pwm == 20_000 and np.log2(r.ICR1 + 1) >= 9
    assert r.TCCR1A & COM1A1
    st = run.status_after(400)
    assert st.status == 0 and st.count == hold
    ref = ar.reference_run(fw.params, surrogate, "mr", 1.4, [hold] * 300)
    fi_ref = float(ref.force_handle_N[-1])
    fi_lim = fw.params.torque_limit_Nm / (fw.params.pulley_radius_mm * 1e-3)
    duty = (r.OCR1A + 1) / (r.ICR1 + 1)
    print(
        f"\nheld at count {hold}: Fi {fi_ref:.4f} N (reference), duty {duty:.5f} = "
        f"{duty * fi_lim:.4f} N at the {fi_lim:g} N limit; PWM {f_pwm:g} Hz"
    )
    assert fi_ref > 0.5
    assert duty * fi_lim == pytest.approx(fi_ref, abs=1.5 * fi_lim / (r.ICR1 + 1))
    assert handle_force_N(fw.params, st.torque_uNm) == pytest.approx(
        fi_ref, abs=0.02 + 0.005 * fi_ref
    )
    assert r.PORTB & 0x01  # DIR (pin 8 = PB0) high: the force pushes the handle open


def test_control_interrupt_rate_and_step_time(fw, tmp_path):
    run = fw.run(homed_script().encoder(150, fw.raw_for(fw.k["GF_N_LO"] + 50)), 300, tmp_path)
    start, end = run.step_start_ms, run.step_end_ms
    sel = start > 50
    period = np.diff(start[sel])
    dur = (end - start)[sel]
    print(
        f"\ncontrol step: period mean {period.mean():.6f} ms, min {period.min():.4f}, max "
        f"{period.max():.4f}; step {dur.mean() * 1e3:.0f} us mean, {dur.max() * 1e3:.0f} us max"
    )
    assert period.mean() == pytest.approx(1.0, rel=1e-4)
    assert period.max() - period.min() < 0.05  # jitter < 50 us (encoder, serial, millis ISRs)
    assert dur.max() < 0.5  # half the period at most
    r = run.at(200)
    assert r.TCCR2A == 0x02 and r.OCR2A == 249 and r.TCCR2B == 4 and r.TIMSK2 & 0x02


def test_faster_control_rate(surrogate, tmp_path):
    b = build(surrogate, tmp_path / "e", ControllerParams(sample_time_s=5e-4))
    run = b.run(homed_script(), 120, tmp_path / "r")
    period = np.diff(run.step_start_ms[run.step_start_ms > 30])
    assert period.mean() == pytest.approx(0.5, rel=1e-4)
    assert any("rate 2000 Hz" in s for _, s in run.lines)


def test_no_torque_until_homed_then_homing_checks_the_count(fw, tmp_path):
    hold = fw.k["GF_N_LO"] + 100
    script = sb.BenchScript().pin(4, 1, 0).encoder(100, 0).send(110, "S").home(150)
    script.encoder(152, 0)
    script.encoder(300, fw.raw_for(hold)).send(320, "S").encoder(330, fw.raw_for(hold))
    script.encoder(400, 40).home(420).send(440, "S")
    run = fw.run(script, 460, tmp_path)
    s0, s1, s2 = run.status_after(110), run.status_after(320), run.status_after(440)
    assert s0.has("not_homed") and s0.has("motor_off")
    assert run.at(100).TCCR1A & (COM1A1 | COM1B1) == 0  # outputs disconnected
    assert s1.status == 0 and s1.count == hold and run.at(310).TCCR1A & COM1A1
    # home pressed again 40 counts away from where it was: lost counts = encoder fault
    assert s2.has("encoder") and s2.has("motor_off")
    assert run.at(440).TCCR1A & (COM1A1 | COM1B1) == 0


def test_watchdog_fires_on_a_stalled_loop(fw, tmp_path):
    script = homed_script().encoder(60, fw.raw_for(fw.k["GF_N_LO"] + 100)).send(100, "X loop")
    run = fw.run(script.send(200, "C").home(210).send(230, "S"), 240, tmp_path)
    assert len(run.resets_ms) == 1
    t_stall = 100 + 7 * 0.09  # "X loop" and its newline received
    off = run.samples[(run.samples.t_ms > t_stall) & ((run.samples.TCCR1A & COM1A1) == 0)]
    t_off = float(off.t_ms.iloc[0])
    print(
        f"\nloop stalled at {t_stall} ms: motor off after {t_off - t_stall:.1f} ms, watchdog "
        f"reset after {run.resets_ms[0] - t_stall:.1f} ms"
    )
    assert t_off - t_stall <= fw.config.loop_timeout_ms + 2
    assert 0 < run.resets_ms[0] - t_off <= 1.2 * fw.config.watchdog_ms + 5
    boots = [s for _, s in run.lines if s.startswith("BOOT")]
    assert len(boots) == 2 and "watchdog" in boots[1]
    st = [s for t, s in run.status() if t > run.resets_ms[0]]
    assert st[0].has("watchdog") and st[0].has("not_homed") and st[0].has("motor_off")
    assert st[-1].status == 0  # cleared with C and homed again: running


def test_watchdog_fires_with_interrupts_off(fw, tmp_path):
    run = fw.run(homed_script().send(60, "X cli"), 140, tmp_path)
    assert len(run.resets_ms) == 1
    assert 0 < run.resets_ms[0] - 60.5 <= 1.2 * fw.config.watchdog_ms + 2


def test_overrun_latches_the_safe_state(fw, tmp_path):
    run = fw.run(homed_script().send(50, "X slow").send(80, "S"), 90, tmp_path)
    st = run.status_after(80)
    assert st.has("overrun") and st.has("motor_off") and st.overruns > 0
    assert run.at(85).TCCR1A & (COM1A1 | COM1B1) == 0


def test_encoder_faults(fw, tmp_path):
    script = homed_script().glitch(40).send(50, "S").send(60, "C").send(70, "S")
    script.encoder(75, 0).encoder(90, -200).send(
        120, "S"
    )  # beyond the open end by more than the margin
    run = fw.run(script, 130, tmp_path)
    s = [run.status_after(t) for t in (50, 70, 120)]
    assert s[0].has("encoder") and s[0].has("motor_off")
    assert s[1].status == 0
    assert s[2].has("encoder")


def test_corrupted_table_keeps_the_motor_off(fw, tmp_path):
    nm = subprocess.run(["avr-nm", str(fw.elf)], capture_output=True, text=True, check=True).stdout
    addr = next(int(ln.split()[0], 16) for ln in nm.splitlines() if ln.endswith(" gf_mr_y"))
    script = sb.BenchScript().corrupt_flash(0, addr + 3, 0x5A).pin(4, 1, 0).home(20)
    run = fw.run(script.send(40, "C").send(60, "S"), 70, tmp_path)
    assert any("table CRC mismatch" in s for _, s in run.lines)
    assert any(s.startswith("ERR C table CRC") for _, s in run.lines)
    st = run.status_after(60)
    assert st.has("table") and st.has("motor_off")


def test_saturation_beyond_its_timeout_is_a_fault(surrogate, tmp_path):
    p = ControllerParams(torque_limit_Nm=0.01)
    b = build(surrogate, tmp_path / "e", p)
    hold = b.k["GF_N_LO"] + 5
    script = homed_script().encoder(60, b.raw_for(hold)).send(R_MS := 300, "S").send(700, "S")
    run = b.run(script, 720, tmp_path / "r")
    s_early, s_late = run.status_after(R_MS), run.status_after(700)
    assert s_early.flags & 0x08 and not s_early.has("saturation")  # saturated, not for long
    assert s_late.has("saturation") and s_late.has("motor_off")
    assert R_MS < 60 + b.config.saturation_timeout_ms < 700


def test_serial_commands_change_the_case(fw, surrogate, tmp_path):
    hold = fw.k["GF_N_LO"] + (fw.k["GF_N_CONTACT"] - fw.k["GF_N_LO"]) // 4
    script = homed_script().encoder(100, fw.raw_for(hold)).send(150, "S")
    for i, cmd in enumerate(
        ["M le", "T 2000", "T 9000", "T 1.5", "M xx", "R 5", "R 0", "Q", "x" * 40, "S"]
    ):
        script.send(160 + 10 * i, cmd)
    run = fw.run(script, 300, tmp_path)
    answers = [s for t, s in run.lines if t > 155 and s[:2] in ("OK", "ER")]
    assert answers[:2] == ["OK M le", "OK T 2000"]
    assert answers[2].startswith("ERR T 9000") and answers[3].startswith("ERR T thickness")
    assert answers[4].startswith("ERR M unknown material 'xx'")
    assert answers[5].startswith("ERR R") and answers[6] == "OK R 0"
    assert answers[7].startswith("ERR unknown command 'Q'") and answers[8].startswith("ERR line")
    before, after = run.status_after(150), run.status_after(250)
    assert (before.material, before.thickness_um) == ("mr", 1400)
    assert (after.material, after.thickness_um) == ("le", 2000)
    for st, mat, t in ((before, "mr", 1.4), (after, "le", 2.0)):
        ref = ar.reference_run(fw.params, surrogate, mat, t, [hold] * 300).force_handle_N[-1]
        fi = handle_force_N(fw.params, st.torque_uNm)
        print(f"\n{mat} {t} mm at count {hold}: firmware {fi:.4f} N, reference {ref:.4f} N")
        assert fi == pytest.approx(ref, abs=0.02 + 0.005 * ref)
    assert after.torque_uNm > before.torque_uNm  # the stiffer case


def test_serial_protocol_refuses_a_material_not_in_the_export(surrogate_mr_le, tmp_path):
    """Issue 16: the firmware of a sweep without nh boots (table CRC good), refuses 'M nh' with
    an error naming the covered materials and keeps its case; 'M le' works."""
    b = build(surrogate_mr_le, tmp_path / "e")
    assert b.k["GF_N_MATERIALS"] == 3  # codes kept: 0 mr, 1 nh (empty), 2 le
    assert '#define GF_MATERIAL_LIST "mr, le"' in (b.sketch / "grasp_firmware.h").read_text()
    script = homed_script().send(40, "S")
    for i, cmd in enumerate(["M nh", "S", "M le", "S", "C"]):
        script.send(50 + 10 * i, cmd)
    run = b.run(script, 120, tmp_path / "r")
    assert not any("CRC mismatch" in s for _, s in run.lines)
    answers = [s for t, s in run.lines if t > 45 and s[:2] in ("OK", "ER")]
    assert answers[0] == "ERR M material 'nh' not in this export's tables (mr, le)"
    assert answers[1] == "OK M le" and answers[2].startswith("OK C")
    assert run.status_after(60).material == "mr" and run.status_after(80).material == "le"


def test_in1_in2_driver_puts_the_pwm_on_one_input(surrogate, tmp_path):
    b = build(surrogate, tmp_path / "e", driver="in1_in2")
    k = b.k
    hold = k["GF_N_LO"] + (k["GF_N_CONTACT"] - k["GF_N_LO"]) // 4
    # close onto the tissue, then open fast: the damping pushes the handle closed (force < 0)
    script = homed_script().send(25, "R 10").encoder(150, b.raw_for(hold)).encoder(161, 0)
    run = b.run(script, 200, tmp_path / "r")
    assert min(st.torque_uNm for _, st in run.status()) < 0
    s = run.samples[run.samples.t_ms > 25]
    a_on, b_on = (s.TCCR1A & COM1A1) > 0, (s.TCCR1A & COM1B1) > 0
    assert not (a_on & b_on).any()  # never both inputs driven
    assert a_on.any() and b_on.any()
    assert ((s.PORTB[~a_on] & 0x02) == 0).all() and ((s.PORTB[~b_on] & 0x04) == 0).all()


def test_locked_anti_phase_driver(surrogate, tmp_path):
    b = build(surrogate, tmp_path / "e", driver="lap")
    k = b.k
    hold = k["GF_N_LO"] + (k["GF_N_CONTACT"] - k["GF_N_LO"]) // 4
    script = sb.BenchScript().pin(4, 1, 0).encoder(19, 0).home(20).encoder(22, 0)
    run = b.run(script.encoder(100, b.raw_for(hold)), 150, tmp_path / "r")
    before, after = run.at(15), run.at(140)
    assert before.PORTD & 0x80 == 0  # enable (pin 7 = PD7) low until homed
    assert after.PORTD & 0x80 and after.TCCR1A & (COM1A1 | COM1B1 | COM1B0) == 0xB0
    assert after.OCR1A == after.OCR1B
    half = (after.ICR1 + 1) // 2
    assert after.OCR1A + 1 > half  # the force pushes the handle open: duty above 50 %


def test_pin_checks_at_compile_time(fw, tmp_path):
    """Editing the generated pins into a conflict stops the build with the header's #error."""
    sk = copy_sketch(fw, tmp_path)
    h = sk / "grasp_firmware.h"
    h.write_text(h.read_text().replace("#define GF_PIN_HOME 4", "#define GF_PIN_HOME 12"))
    with pytest.raises(RuntimeError, match="GF_PIN_SCOPE and GF_PIN_HOME are the same pin"):
        sb.build_sketch(sk)


def test_sketch_builds_with_arduino_builder(fw, tmp_path):
    need("arduino-builder", "arduino-builder")
    sk = copy_sketch(fw, tmp_path)
    res = subprocess.run(
        ["sh", "build_arduino_builder.sh"], cwd=sk, capture_output=True, text=True, timeout=600
    )
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert (sk / "build-builder" / "grasprom_controller.ino.hex").is_file()
    print("\n" + "\n".join(ln for ln in res.stdout.splitlines() if "bytes" in ln))
