#!/usr/bin/env node
// The Raspberry Pi Pico firmware-in-the-loop bench: runs the unchanged firmware image on
// rp2040js and speaks the line protocol of fil/PROTOCOL.md on stdin/stdout, one answer line per
// request line. Diagnostics go to stderr.
//
//   node fil/pico/bench.mjs <image.elf> [--rtt FILE]

import { appendFileSync, readFileSync } from 'node:fs';
import { createInterface } from 'node:readline';

const HEX = /^([0-9a-f]{2})*$/;
/**
 * With FIL_PICO_PROFILE=K in the environment the bench profiles every millisecond it measures
 * by function and logs the K busiest ones' cycles by function at the end (after `load:`).
 */
const PROFILE_ENV = 'FIL_PICO_PROFILE';

/** Parses one request line into a call on `bench`; returns the answer line. Throws on errors. */
export function handle(bench, line) {
  const words = line.trim().split(/\s+/);
  switch (words[0]) {
    case 'step': {
      if (words.length !== 12) throw new Error(`step takes 11 arguments, got ${words.length - 1}`);
      const us = parseDecimal(words[1], 'us', 1e9);
      const sensors = words.slice(2, 11).map((w, i) => parseDecimal(w, `s${i}`, 4095));
      const rx = parseHex(words[11], 'rx');
      const r = bench.step(us, sensors, rx);
      const tx = r.tx.length ? Buffer.from(r.tx).toString('hex') : '-';
      return `ok ${r.motors.join(' ')} ${tx} ${r.resets} ${r.erases} ${r.programs}`;
    }
    case 'power':
      if (words.length === 2 && words[1] === 'off') bench.powerOff();
      else if (words.length === 2 && words[1] === 'on') bench.powerOn();
      else throw new Error(`power takes on or off: ${line.trim()}`);
      return 'ok';
    case 'hang':
      if (words.length !== 1) throw new Error('hang takes no argument');
      bench.hang();
      return 'ok';
    default:
      throw new Error(`unknown request: ${line.trim()}`);
  }
}

function parseDecimal(word, name, max) {
  if (!/^\d+$/.test(word) || Number(word) > max) throw new Error(`${name}: not 0..=${max}: ${word}`);
  return Number(word);
}

function parseHex(word, name) {
  if (word === '-') return [];
  if (!HEX.test(word)) throw new Error(`${name}: not lowercase hex bytes: ${word}`);
  return [...Buffer.from(word, 'hex')];
}

async function main(argv) {
  const args = argv.slice(2);
  let rttFile = null;
  const rttAt = args.indexOf('--rtt');
  if (rttAt >= 0) {
    rttFile = args[rttAt + 1];
    args.splice(rttAt, 2);
  }
  const out = (line) => process.stdout.write(`${line}\n`);
  if (args.length !== 1 || !rttFile && rttAt >= 0) {
    out('error usage: node fil/pico/bench.mjs <image.elf> [--rtt FILE]');
    process.exit(1);
  }
  const log = (msg) => process.stderr.write(`pico-bench: ${msg}\n`);
  let bench;
  let rtt = null;
  try {
    // Loaded here, so that a missing `npm ci` is answered `error` like any other failure.
    const { Bench } = await import('./bench-core.mjs').catch((e) => {
      throw new Error(`rp2040js is not installed (run npm ci in fil/pico): ${e.message}`);
    });
    const { RttReader } = await import('./rtt.mjs');
    const elf = readFileSync(args[0]);
    const keep = Number(process.env[PROFILE_ENV] || 0);
    const { symbolNamer } = await import('./symbols.mjs');
    const profile = keep > 0 ? { keep, nameOf: symbolNamer(args[0]) } : null;
    bench = new Bench(elf, { log, profile });
    if (rttFile) rtt = new RttReader(elf, (bytes) => appendFileSync(rttFile, bytes));
  } catch (e) {
    out(`error ${e.message}`);
    process.exit(1);
  }
  out('ready pico 3 thesis');
  const lines = createInterface({ input: process.stdin, crlfDelay: Infinity });
  for await (const line of lines) {
    if (line.trim() === '') continue;
    if (line.trim() === 'quit') {
      log(bench.loadSummary());
      bench.profileReport().forEach(log);
      break;
    }
    let answer;
    try {
      answer = handle(bench, line);
      if (rtt && bench.chip) rtt.poll(bench.chip.rp2040);
    } catch (e) {
      out(`error ${e.message.replace(/\s+/g, ' ')}`);
      process.exit(1);
    }
    out(answer);
  }
  process.exit(0);
}

if (process.argv[1] && import.meta.url === new URL(`file://${process.argv[1]}`).href) {
  main(process.argv);
}
