// One test per patch of patches.mjs (and the watchdog reset of chip.mjs), on a chip without
// firmware whose registers the test drives. Each fails with its patch left out:
//   FIL_PICO_DISABLE=uart-registers|uart-tx|uart-receive|adc-dreq|xip-ctrl|sev|aircr|udf|watchdog npm test

import assert from 'node:assert/strict';
import { test } from 'node:test';
import { ADC, B_SELF, DMA, RAM, armAdcDma, bareChip, runCode } from './helpers.mjs';

const UART0 = 0x40034000;
const UART0_IRQ = 20;
const DREQ_UART0_RX = 21;

function enableUart(rp2040) {
  rp2040.writeUint32(UART0 + 0x30, (1 << 9) | (1 << 8) | 1); // UARTCR: RXE | TXE | UARTEN
}

test('uart-registers: RSR, ILPR, IFLS and DMACR hold what is written (rp2040js reads 0xffffffff)', () => {
  const { rp2040 } = bareChip();
  assert.equal(rp2040.readUint32(UART0 + 0x04), 0, 'UARTRSR: no receive error');
  for (const offset of [0x20, 0x34, 0x48]) {
    rp2040.writeUint32(UART0 + offset, 0x1);
    assert.equal(rp2040.readUint32(UART0 + offset), 0x1, `offset 0x${offset.toString(16)}`);
    rp2040.writeUint32(UART0 + offset, 0x0);
    assert.equal(rp2040.readUint32(UART0 + offset), 0x0, `offset 0x${offset.toString(16)}`);
  }
});

test('uart-tx: the TX interrupt is raised by a write of DR and cleared by ICR, not forever', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  enableUart(rp2040);
  const pending = () => !!(rp2040.core.pendingInterrupts & (1 << UART0_IRQ));
  rp2040.writeUint32(UART0 + 0x38, 1 << 5); // UARTIMSC: TXIM
  assert.equal(pending(), false, 'TXIM alone raises nothing');
  rp2040.writeUint32(UART0 + 0x00, 0x41);
  assert.deepEqual(chip.tx, [0x41]);
  assert.equal(pending(), true, 'the FIFO drained after the write');
  rp2040.writeUint32(UART0 + 0x44, 1 << 5); // UARTICR: TXIC
  assert.equal(pending(), false, 'cleared by ICR');
  rp2040.writeUint32(UART0 + 0x38, 1 << 5);
  assert.equal(pending(), false, 'and not raised again by a mask write');
});

test('uart-receive: bytes reach a DMA channel paced by UART0 RX DREQ; lost while disabled', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  const uart = rp2040.uart[0];
  chip.receive(0x11); // before UARTEN: lost on the line
  assert.equal(uart.rxFIFO.itemCount, 0);
  enableUart(rp2040);
  chip.receive(0x22); // waits in the FIFO until the DMA is on
  rp2040.writeUint32(UART0 + 0x48, 1); // UARTDMACR: RXDMAE
  const ch = DMA + 2 * 0x40; // channel 2, as uart_ring.rs
  rp2040.writeUint32(ch + 0x00, UART0); // READ_ADDR: UARTDR
  rp2040.writeUint32(ch + 0x04, RAM + 0x100); // WRITE_ADDR
  rp2040.writeUint32(ch + 0x08, 10); // TRANS_COUNT
  // CTRL_TRIG: EN, byte, INCR_WRITE, CHAIN_TO itself, TREQ_SEL UART0 RX
  rp2040.writeUint32(ch + 0x0c, 1 | (1 << 5) | (2 << 11) | (DREQ_UART0_RX << 15));
  rp2040.clock.tick(0);
  for (const byte of [0x33, 0x44]) chip.receive(byte);
  rp2040.clock.tick(0);
  const ram = [0, 1, 2].map((i) => rp2040.readUint8(RAM + 0x100 + i));
  assert.deepEqual(ram, [0x22, 0x33, 0x44]);
  assert.equal(rp2040.readUint32(ch + 0x08), 7, 'TRANS_COUNT counts the bytes moved');
  assert.equal(uart.rxFIFO.itemCount, 0);
});

test('uart-receive: a byte arriving at a full FIFO is lost and sets UARTRSR.OE', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  enableUart(rp2040);
  for (let i = 0; i < 33; i++) chip.receive(i);
  assert.equal(rp2040.readUint32(UART0 + 0x04) & 0x8, 0x8, 'OE');
  assert.equal(rp2040.readUint32(UART0 + 0x00) & 0xff, 0, 'the FIFO kept the oldest bytes');
  rp2040.writeUint32(UART0 + 0x04, 0); // ECR
  assert.equal(rp2040.readUint32(UART0 + 0x04), 0);
});

test('adc-dreq: a FIFO drained with DREQ_EN clear requests nothing; the DMA waits for conversions', () => {
  const { rp2040 } = bareChip();
  const fcs = (dreq) => rp2040.writeUint32(ADC + 0x08, (1 << 24) | (dreq ? 1 << 3 : 0) | 1); // THRESH 1, EN
  rp2040.writeUint32(ADC + 0x00, 1); // CS: EN
  fcs(true);
  rp2040.writeUint32(ADC + 0x00, 1 | (1 << 2)); // START_ONCE: one conversion into the FIFO
  rp2040.clock.tick(3000);
  assert.equal((rp2040.readUint32(ADC + 0x08) >> 16) & 0xf, 1, 'FIFO level 1: the request raised');
  fcs(false); // as embassy-rp's read_many ends: DREQ_EN cleared with the entry left
  rp2040.readUint32(ADC + 0x0c); // and its next call drains the FIFO, then sets DREQ_EN
  fcs(true);
  const ch = armAdcDma(rp2040, RAM + 0x200, 2);
  rp2040.clock.tick(0);
  assert.equal(rp2040.readUint32(ch + 0x08), 2, 'nothing moved from the empty FIFO');
  assert.equal(rp2040.readUint32(ADC + 0x08) & (1 << 10), 0, 'FCS.UNDER: no read of the empty FIFO');
  rp2040.writeUint32(ADC + 0x00, 1 | (1 << 2)); // a conversion: one transfer
  rp2040.clock.tick(3000);
  assert.equal(rp2040.readUint32(ch + 0x08), 1, 'one conversion, one transfer');
});

test('xip-ctrl: STAT says flush ready and FIFO empty, STREAM_CTR reads 0, no unmapped access', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  rp2040.writeUint32(0x14000004, 1); // FLUSH
  assert.equal(rp2040.readUint32(0x14000008) & 0x3, 0x3);
  assert.equal(rp2040.readUint32(0x14000018), 0);
  assert.equal(chip.error, null);
});

test('sev: SEV sets the event register, so the WFE after it does not sleep', () => {
  const chip = bareChip();
  const { core } = chip.rp2040;
  runCode(chip, RAM, [0xbf40 /* sev */, 0xbf20 /* wfe */, B_SELF]);
  core.executeInstruction();
  core.executeInstruction();
  assert.equal(core.waiting, false);
  assert.equal(core.PC, RAM + 4);
  core.executeInstruction(); // b .
  runCode(chip, RAM, [0xbf20]);
  core.executeInstruction();
  assert.equal(core.waiting, true, 'without an event, WFE sleeps');
});

test('aircr: a write of VECTKEY and SYSRESETREQ requests a reset; a wrong key does not', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  assert.equal(rp2040.readUint32(0xe000ed0c) >>> 16, 0xfa05, 'VECTKEYSTAT');
  rp2040.writeUint32(0xe000ed0c, 0x12340004);
  assert.equal(chip.resetRequest, null);
  rp2040.writeUint32(0xe000ed0c, 0x05fa0004);
  assert.equal(chip.resetRequest, 'sysresetreq');
});

test('udf: UDF enters the HardFault handler with the UDF as the stacked return address', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  const { core } = rp2040;
  const table = RAM + 0x1000;
  rp2040.writeUint32(table + 3 * 4, RAM + 0x201); // HardFault vector (Thumb)
  rp2040.writeUint32(0xe000ed08, table); // VTOR
  core.SP = RAM + 0x2000;
  runCode(chip, RAM + 0x100, [0xde00 /* udf #0 */, B_SELF]);
  core.executeInstruction();
  assert.equal(chip.takeFault(), true);
  assert.equal(core.PC & ~1, RAM + 0x200);
  assert.equal(core.IPSR, 3);
  assert.equal(rp2040.readUint32(core.SP + 0x18), RAM + 0x100, 'return address: the UDF');
  assert.equal(chip.error, null);
});

test('udf: BKPT is a breakpoint: the bench reports an error', () => {
  const chip = bareChip();
  runCode(chip, RAM + 0x100, [0xbe00 /* bkpt #0 */]);
  chip.rp2040.core.executeInstruction();
  assert.equal(chip.takeFault(), false);
  assert.match(chip.error ?? '', /breakpoint/);
});

test('watchdog: on expiry the chip asks for a reset (REASON: TIMER), the CPU stops', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  runCode(chip, RAM, [B_SELF]);
  // rp2040js alone logs and goes on, its alarm firing again and again at the same instant.
  const wd = rp2040.peripherals[0x40058];
  const trigger = wd.onWatchdogTrigger;
  let fired = 0;
  wd.onWatchdogTrigger = () => {
    if (++fired > 100) throw new Error('the watchdog fired 100 times without a reset');
    trigger();
  };
  rp2040.writeUint32(0x40058004, 2000); // LOAD: 1 ms of 2 MHz decrements (RP2040-E1)
  rp2040.writeUint32(0x40058000, 1 << 30); // CTRL: ENABLE
  chip.run(900_000);
  assert.equal(chip.resetRequest, null);
  chip.run(5_000_000);
  assert.equal(chip.resetRequest, 'watchdog');
  assert.equal(rp2040.readUint32(0x40058008), 1, 'REASON: TIMER');
  assert.ok(chip.nanos < 1_100_000, `stopped at the expiry (${chip.nanos} ns)`);
});
