// Fixes to rp2040js 1.4.1 (pinned exactly in package.json) that the unchanged Pico firmware
// needs. Each function patches one emulated chip in place and names what rp2040js gets wrong
// and what the RP2040 datasheet (RP2040 Datasheet, build 2023-06, "RP2040 DS") or the ARMv6-M
// Architecture Reference Manual says. They reach into rp2040js's internals, hence the pinned
// version and one test per patch (test/patches.test.mjs) that fails without it.
// The QSPI flash model is in flash-model.mjs; the watchdog / reset handling lives in chip.mjs.

import { BasePeripheral } from 'rp2040js';

/**
 * `FIL_PICO_DISABLE=name,name` leaves those patches out (names: the `disabled('...')` calls
 * below, and `flash` for flash-model.mjs), to watch their tests fail.
 */
const DISABLED = new Set((process.env.FIL_PICO_DISABLE ?? '').split(',').filter(Boolean));
export function disabled(name) {
  return DISABLED.has(name);
}

const UART_DR = 0x00;
const UART_ICR = 0x44;
const UART_DMACR = 0x48;
const UART_TXINTR = 1 << 5;
const UART_RXDMAE = 1 << 0;

/**
 * PL011 registers rp2040js does not model: UARTRSR/ECR (0x04), UARTILPR (0x20), UARTIFLS (0x34)
 * and UARTDMACR (0x48) fall through to BasePeripheral and read 0xffffffff, so embassy-rp's
 * UART interrupt handler believes RX DMA is on and every error bit is set. RP2040 DS 4.2.8:
 * they are plain read/write registers (RSR's error bits clear on any write to ECR; only the
 * overrun bit is ever raised, by patchUartReceive).
 */
export function patchUartRegisters(uart) {
  if (disabled('uart-registers')) {
    uart.dmaControl = () => 0xffffffff; // what rp2040js reads for UARTDMACR
    uart.setOverrun = () => {};
    return;
  }
  const stored = new Map([[0x04, 0], [0x20, 0], [0x34, 0x12], [0x48, 0]]);
  const read = uart.readUint32.bind(uart);
  const write = uart.writeUint32.bind(uart);
  uart.readUint32 = (offset) => (stored.has(offset) ? stored.get(offset) : read(offset));
  uart.writeUint32 = (offset, value) => {
    if (offset === 0x04) stored.set(0x04, 0); // ECR: a write clears the error flags
    else if (stored.has(offset)) stored.set(offset, value >>> 0);
    else write(offset, value);
  };
  uart.dmaControl = () => stored.get(0x48);
  uart.setOverrun = () => stored.set(0x04, stored.get(0x04) | 0x8);
}

/**
 * The TX interrupt: rp2040js's checkInterrupts() sets TXRIS at every check, so an unmasked TXIM
 * interrupts forever (embassy keeps TXIM on and waits for the FIFO to drain: an interrupt
 * storm). RP2040 DS 4.2.6 (UARTTXINTR): the transmit interrupt is raised when the FIFO level
 * passes through the trigger level going down, cleared by writing data or ICR. Here the FIFO
 * drains at once, so TXRIS is raised by each write of DR; the line is RIS & IMSC.
 */
export function patchUartTxInterrupt(uart) {
  if (disabled('uart-tx')) return;
  uart.checkInterrupts = function checkInterrupts() {
    this.rp2040.setInterrupt(this.irq, !!(this.interruptStatus & this.interruptMask));
  };
  const write = uart.writeUint32.bind(uart);
  uart.writeUint32 = (offset, value) => {
    write(offset, value);
    if (offset === UART_DR) {
      uart.interruptStatus |= UART_TXINTR;
      uart.checkInterrupts();
    } else if (offset === UART_ICR) {
      uart.checkInterrupts();
    }
  };
}

/**
 * The receive side. rp2040js's feedByte puts a byte into the FIFO whatever the UART's state and
 * drops it silently when the FIFO is full, and it never raises UART RX DREQ, so a DMA channel
 * paced by it never moves a byte. RP2040 DS 4.2: the UART receives only while UARTCR.UARTEN and
 * RXE are set (bytes on the line before are lost); a byte arriving at a full FIFO is lost and
 * sets the overrun flag (UARTRSR.OE, bit 3; UARTDR.OE); with UARTDMACR.RXDMAE set the UART
 * requests a DMA transfer while its receive FIFO holds data (4.2.5): raised when a byte
 * arrives, dropped when a DR read empties the FIFO. Needs patchUartRegisters first.
 */
export function patchUartReceive(uart) {
  if (disabled('uart-receive')) return;
  const dma = uart.rp2040.dma;
  const feed = uart.feedByte.bind(uart);
  uart.lostBytes = 0;
  uart.feedByte = (value) => {
    if (!uart.enabled || !uart.rxEnabled) {
      uart.lostBytes++;
      return;
    }
    if (uart.rxFIFO.full) {
      uart.lostBytes++;
      uart.setOverrun();
      return;
    }
    feed(value);
    if (uart.dmaControl() & UART_RXDMAE) dma.setDREQ(uart.dreq.rx);
  };
  const read = uart.readUint32.bind(uart);
  uart.readUint32 = (offset) => {
    const value = read(offset);
    if (offset === UART_DR && uart.rxFIFO.empty) dma.clearDREQ(uart.dreq.rx);
    return value;
  };
  // Setting RXDMAE with bytes waiting requests at once; clearing it withdraws the request.
  const write = uart.writeUint32.bind(uart);
  uart.writeUint32 = (offset, value) => {
    write(offset, value);
    if (offset !== UART_DMACR) return;
    if (value & UART_RXDMAE && !uart.rxFIFO.empty) dma.setDREQ(uart.dreq.rx);
    else if (!(value & UART_RXDMAE)) dma.clearDREQ(uart.dreq.rx);
  };
}

const ADC_FCS = 0x08;
const ADC_FIFO = 0x0c;
const ADC_FCS_DREQ_EN = 1 << 3;

/**
 * ADC DREQ. rp2040js raises DREQ_ADC only when a conversion enters the FIFO and withdraws it only
 * when a FIFO read leaves fewer entries than FCS.THRESH, and only while FCS.DREQ_EN is set: a
 * request raised before DREQ_EN is cleared, or the FIFO drained with DREQ_EN clear (or read
 * empty), stays raised, so the next DMA channel paced by it moves that many words at once from
 * the empty FIFO (zeros, FCS.UNDER). embassy-rp's `Adc::read_many` does exactly that sequence
 * (it leaves the conversions that end after the DMA's last transfer in the FIFO, clears DREQ_EN,
 * and at its next call drains the FIFO before setting DREQ_EN): every read after the first
 * completes at once with zeros. RP2040 DS 4.9.3 (FCS.DREQ_EN, THRESH): the ADC requests a DMA
 * transfer while DREQ_EN is set and the FIFO holds at least THRESH entries; here re-evaluated
 * at every FIFO push and read and every FCS write.
 */
export function patchAdcDreq(adc) {
  if (disabled('adc-dreq')) return;
  const dma = adc.rp2040.dma;
  adc.updateDMA = function updateDMA() {
    const thresh = (this.fcs >>> 24) & 0xf;
    if (this.fcs & ADC_FCS_DREQ_EN && this.fifo.itemCount >= thresh) dma.setDREQ(this.dreq);
    else dma.clearDREQ(this.dreq);
  };
  const read = adc.readUint32.bind(adc);
  adc.readUint32 = (offset) => {
    const value = read(offset);
    if (offset === ADC_FIFO) adc.updateDMA();
    return value;
  };
  const write = adc.writeUint32.bind(adc);
  adc.writeUint32 = (offset, value) => {
    write(offset, value);
    if (offset === ADC_FCS) adc.updateDMA();
  };
}

/**
 * XIP_CTRL (0x14000000) is not mapped in rp2040js: reads log "invalid memory address". The boot
 * ROM's flash_flush_cache writes FLUSH and polls STAT.FLUSH_READY. RP2040 DS 2.6.3.1: STAT =
 * FLUSH_READY (bit 0) | FIFO_EMPTY (bit 1) with no cache and no streaming; STREAM_CTR reads 0.
 */
export class XipCtrl extends BasePeripheral {
  constructor(rp2040) {
    super(rp2040, 'XIP_CTRL');
    this.ctrl = 0x3;
    this.flushes = 0;
  }
  readUint32(offset) {
    switch (offset) {
      case 0x00: return this.ctrl;
      case 0x08: return 0x3; // STAT: FLUSH_READY | FIFO_EMPTY
      default: return 0; // FLUSH, CTR_HIT, CTR_ACC, STREAM_ADDR, STREAM_CTR, STREAM_FIFO
    }
  }
  writeUint32(offset, value) {
    if (offset === 0x00) this.ctrl = value >>> 0;
    else if (offset === 0x04) this.flushes++;
  }
}
export function patchXipCtrl(rp2040) {
  if (disabled('xip-ctrl')) return;
  rp2040.peripherals[0x14000] = new XipCtrl(rp2040);
}

/**
 * SEV (0xBF40): rp2040js only logs 'SEV' at info level; embassy's thread executor wakes itself
 * with SEV before WFE, so the WFE sleeps with work pending. ARMv6-M ARM B1.5.18: SEV sets the
 * event register (of every core). The core calls logger.info('CortexM0Core', 'SEV') on each
 * SEV, so the bench's logger sets the event register there (no per-instruction cost).
 */
export function sevSetsEvent(rp2040, component, message) {
  if (disabled('sev')) return false;
  if (component === 'CortexM0Core' && message === 'SEV') {
    rp2040.core.eventRegistered = true;
    return true;
  }
  return false;
}

/**
 * AIRCR (0xE000ED0C) is not modelled (reads 0xffffffff, writes ignored), so SCB::sys_reset
 * (the firmware's X0/X42 and its HardFault handler) spins forever. ARMv6-M ARM B3.2.6: a write
 * with VECTKEY 0x05FA and SYSRESETREQ (bit 2) requests a system reset; reads give VECTKEYSTAT
 * 0xFA05 in the top half. `onReset` is called; the bench rebuilds the chip.
 */
export function patchAircr(rp2040, onReset) {
  if (disabled('aircr')) return;
  const ppb = rp2040.ppb;
  const read = ppb.readUint32.bind(ppb);
  const write = ppb.writeUint32.bind(ppb);
  ppb.readUint32 = (offset) => (offset === 0xd0c ? 0xfa050000 : read(offset));
  ppb.writeUint32 = (offset, value) => {
    if (offset !== 0xd0c) return write(offset, value);
    if (value >>> 16 === 0x05fa && value & 4) onReset('sysresetreq');
  };
}

/**
 * UDF: rp2040js calls onBreak (meant for a debugger) and executes on. ARMv6-M ARM A6.7.72: UDF
 * is UNDEFINED, which on ARMv6-M escalates to HardFault (panic-probe ends a panic in UDF). Call
 * `takeFault()` after the instruction: it rewinds the PC to the UDF and enters HardFault, so
 * the image's handler runs as on the chip. BKPT stays a break: the bench reports an error.
 */
export function patchUdfFault(rp2040, onBkpt) {
  if (disabled('udf')) return () => false;
  const core = rp2040.core;
  let pending = false;
  rp2040.onBreak = (code) => {
    const pc = (core.PC - 2) >>> 0; // while onBreak runs, PC is 2 past the (first) halfword
    const opcode = rp2040.readUint16(pc & ~1);
    if (opcode >> 8 === 0xde || opcode >> 4 === 0xf7f) pending = true;
    else onBkpt(code, pc);
  };
  return function takeFault() {
    if (!pending) return false;
    pending = false;
    // After the instruction PC is past the whole UDF (2 or 4 bytes, breakRewind): back to it.
    core.PC = (core.PC - core.breakRewind) >>> 0;
    core.exceptionEntry(3);
    return true;
  };
}
