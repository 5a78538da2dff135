// One emulated Raspberry Pi Pico: an rp2040js RP2040 with the boot ROM, the patches
// (patches.mjs), the QSPI flash model (flash-model.mjs) and the board around the chip as the
// firmware's pin map wires it (src/board/pico/mod.rs): the CD74HC4067 multiplexer in front of
// ADC0, the button, the TB6612FNG inputs read back, UART0 to the printer.
//
// A Chip lives from one reset to the next: a watchdog reset, a software reset request or a
// power cycle makes the bench build a new Chip that takes over the flash (and, for a watchdog
// reset, the watchdog's REASON and SCRATCH registers, which survive it: RP2040 DS 4.7.3).
// Execution starts at boot2 (0x10000000), as rp2040js's own demo does: the ROM's flash boot
// path (checksum of boot2 read through the SSI) needs a real SSI.

import { RP2040 } from 'rp2040js';
import { attachFlash } from './flash-model.mjs';
import {
  patchAdcDreq, patchAircr, patchUartReceive, patchUartRegisters, patchUartTxInterrupt, patchUdfFault,
  disabled, patchXipCtrl, sevSetsEvent,
} from './patches.mjs';

export const FLASH_BYTES = 2 * 1024 * 1024;
const NANOS_PER_CYCLE = 8; // 125 MHz clk_sys; rp2040js counts fixed cycles per instruction
const WATCHDOG = 0x40058;
const FUNCTION_PWM = 4;

/** Sensor i sits on multiplexer channel i ^ (i >> 1) (`MUX_CHANNEL`, src/board/pico/mod.rs). */
export const MUX_CHANNEL = Array.from({ length: 9 }, (_, i) => i ^ (i >> 1));
const SENSOR_OF_CHANNEL = new Map(MUX_CHANNEL.map((channel, sensor) => [channel, sensor]));
const MUX_SELECT = [2, 3, 4, 5]; // S0..S3
const BUTTON = 17;
/** Each slot's TB6612 pins: STBY, IN1, IN2, and PWM (slice, channel B?). */
export const SLOT_PINS = [
  { stby: 13, in1: 9, in2: 10, pwm: 6, slice: 3, b: false },
  { stby: 13, in1: 11, in2: 12, pwm: 7, slice: 3, b: true },
  { stby: 16, in1: 14, in2: 15, pwm: 8, slice: 4, b: false },
];

export class Chip {
  /**
   * @param {object} o
   * @param {Uint8Array} o.bootrom 16 KiB boot ROM
   * @param {Uint8Array} o.flash the flash contents to start from (FLASH_BYTES)
   * @param {{erases:number, programs:number}} o.counters flash operation counters (shared)
   * @param {{reason:number, scratch:Uint32Array}|null} o.watchdog carried over, or power-on
   * @param {(msg:string)=>void} o.log diagnostics (stderr)
   */
  constructor({ bootrom, flash, counters, watchdog = null, log = () => {} }) {
    /** Instructions executed and the cycles they took (rp2040js's Cortex-M0+ timings): the load. */
    this.executed = 0;
    this.busyCycles = 0;
    /** Cycles by instruction address while a Map is set here (the bench's profiles). */
    this.pcCycles = null;
    this.log = log;
    this.sensors = new Array(9).fill(0);
    this.tx = [];
    this.hung = false;
    this.resetRequest = null; // 'watchdog' | 'sysresetreq' | 'force' once the chip asks
    this.error = null; // an emulation the bench cannot go on with
    this.warned = new Set();

    const rp2040 = new RP2040();
    this.rp2040 = rp2040;
    rp2040.logger = this.makeLogger();
    rp2040.loadBootrom(new Uint32Array(bootrom.buffer, bootrom.byteOffset, bootrom.byteLength / 4));
    rp2040.flash.set(flash.subarray(0, FLASH_BYTES)); // after loadBootrom: its reset() erases
    this.flash = attachFlash(rp2040, counters);

    const uart = rp2040.uart[0];
    patchUartRegisters(uart);
    patchUartTxInterrupt(uart);
    patchUartReceive(uart);
    patchXipCtrl(rp2040);
    patchAircr(rp2040, () => { this.resetRequest ??= 'sysresetreq'; });
    this.takeFault = patchUdfFault(rp2040, (code, pc) => {
      this.error = `breakpoint ${code} at 0x${pc.toString(16)}`;
    });

    const wd = rp2040.peripherals[WATCHDOG];
    if (watchdog) {
      wd.reason = watchdog.reason;
      wd.scratchData.set(watchdog.scratch);
    }
    if (!disabled('watchdog')) wd.onWatchdogTrigger = () => {
      // rp2040js set REASON (TIMER, or FORCE for CTRL.TRIGGER) before calling this.
      wd.timer.enable = false;
      wd.alarm.enable = false;
      this.resetRequest ??= wd.reason & 2 ? 'force' : 'watchdog';
    };

    uart.onByte = (byte) => this.tx.push(byte);
    const adc = rp2040.adc;
    patchAdcDreq(adc);
    adc.onADCRead = (channel) => {
      // The conversion samples the input at its start; the multiplexer passes the sensor of
      // the channel its select lines pick (channels no sensor is wired to read 0).
      adc.currentChannel = channel;
      adc.channelValues[channel] = channel === 0 ? this.muxValue() : 0;
      adc.sampleAlarm.schedule(adc.sampleTime * 1000);
    };
    rp2040.gpio[BUTTON].setInputValue(true); // the button, pulled up, not pressed

    rp2040.core.PC = 0x10000000; // boot2
  }

  makeLogger() {
    const chip = this;
    const once = (key, msg) => {
      if (!chip.warned.has(key)) {
        chip.warned.add(key);
        chip.log(msg);
      }
    };
    return {
      debug() {},
      info(component, message) {
        if (sevSetsEvent(chip.rp2040, component, message)) return;
        once(`${component}:${message}`, `[${component}] ${message}`);
      },
      warn(component, message) {
        if (/invalid memory address|undefined address|not implemented yet/.test(message)) {
          chip.error ??= `${component}: ${message} (pc 0x${chip.rp2040.core.PC.toString(16)})`;
        }
        once(`${component}:${message}`, `[${component}] ${message}`);
      },
      error(component, message) {
        chip.error ??= `${component}: ${message}`;
      },
    };
  }

  get nanos() {
    return this.rp2040.clock.nanos;
  }

  /** The watchdog's registers that survive a watchdog reset. */
  get watchdogState() {
    const wd = this.rp2040.peripherals[WATCHDOG];
    return { reason: wd.reason, scratch: Uint32Array.from(wd.scratchData) };
  }

  muxValue() {
    let channel = 0;
    MUX_SELECT.forEach((pin, bit) => {
      if (this.pinLevel(pin)) channel |= 1 << bit;
    });
    const sensor = SENSOR_OF_CHANNEL.get(channel);
    return sensor === undefined ? 0 : this.sensors[sensor];
  }

  /** A pin's level as the board sees it: driven high, else low (pull-downs, or floating). */
  pinLevel(pin) {
    const gpio = this.rp2040.gpio[pin];
    return gpio.outputEnable && gpio.outputValue ? 1 : 0;
  }

  /** The PWM input's duty in per mille: a PWM-driven pin from its slice, else its level. */
  duty({ pwm, slice, b }) {
    const gpio = this.rp2040.gpio[pwm];
    if (!gpio.outputEnable) return 0;
    if (gpio.functionSelect !== FUNCTION_PWM) return gpio.outputValue ? 1000 : 0;
    const channel = this.rp2040.pwm.channels[slice];
    const cc = b ? channel.cc >>> 16 : channel.cc & 0xffff;
    const inverted = channel.csr & (b ? 1 << 3 : 1 << 2);
    let duty = channel.csr & 1 ? Math.min(1000, Math.round((cc * 1000) / (channel.top + 1))) : 0;
    if (inverted) duty = 1000 - duty;
    return duty;
  }

  /** Each slot's `<STBY><IN1><IN2>:<duty>`. */
  motors() {
    return SLOT_PINS.map((p) => `${this.pinLevel(p.stby)}${this.pinLevel(p.in1)}${this.pinLevel(p.in2)}:${this.duty(p)}`);
  }

  /** One byte from the printer into UART0's receive FIFO. */
  receive(byte) {
    this.rp2040.uart[0].feedByte(byte);
  }

  /**
   * Runs until the chip's clock reaches `untilNanos` (it may pass it by the last instruction's
   * cycles), a reset request, or an error. A waiting (WFE/WFI) or hung core jumps to the next
   * timer event; alarms (TIMER, DMA, ADC, PWM, watchdog) run inside clock.tick.
   */
  run(untilNanos) {
    const { core, clock } = this.rp2040;
    while (clock.nanos < untilNanos && !this.resetRequest && !this.error) {
      if (this.hung || core.waiting) {
        const next = clock.nextAlarm ? clock.nextAlarm.nanos : Infinity;
        clock.tick(Math.min(next, untilNanos) - clock.nanos);
      } else {
        const pc = core.PC;
        const cycles = core.executeInstruction();
        if (this.pcCycles) this.pcCycles.set(pc, (this.pcCycles.get(pc) ?? 0) + cycles);
        this.executed += 1;
        this.busyCycles += cycles;
        this.takeFault();
        // clock.tick(cycles * 8) without its call when no alarm is due: the same time, the
        // same alarms at the same instants.
        clock.nanosCounter += cycles * NANOS_PER_CYCLE;
        if (clock.nextAlarm && clock.nextAlarm.nanos <= clock.nanosCounter) clock.tick(0);
      }
    }
  }
}
