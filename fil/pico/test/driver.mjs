// Test helper: runs `node bench.mjs <image>` as the simulator does and exchanges lines with it.

import { spawn } from 'node:child_process';
import { createInterface } from 'node:readline';
import { fileURLToPath } from 'node:url';

const BENCH = fileURLToPath(new URL('../bench.mjs', import.meta.url));

export class Driver {
  constructor(image, args = []) {
    this.child = spawn(process.execPath, [BENCH, image, ...args], { stdio: ['pipe', 'pipe', 'pipe'] });
    this.stderr = '';
    this.child.stderr.on('data', (d) => { this.stderr += d; });
    this.lines = [];
    this.waiting = [];
    createInterface({ input: this.child.stdout }).on('line', (line) => {
      const next = this.waiting.shift();
      if (next) next(line);
      else this.lines.push(line);
    });
    this.exit = new Promise((resolve) => this.child.on('exit', (code) => resolve(code)));
  }

  /** The next line the bench prints. */
  line() {
    if (this.lines.length) return Promise.resolve(this.lines.shift());
    return new Promise((resolve) => this.waiting.push(resolve));
  }

  /** Sends `request`, returns the answer line. */
  async ask(request) {
    this.child.stdin.write(`${request}\n`);
    return this.line();
  }

  /** A `step` of `us` with idle sensors (or `sensors`) and `rx` (bytes): the parsed answer. */
  async step(rx = [], { us = 1000, sensors = new Array(9).fill(2048) } = {}) {
    const hex = rx.length ? Buffer.from(rx).toString('hex') : '-';
    const answer = await this.ask(`step ${us} ${sensors.join(' ')} ${hex}`);
    const m = /^ok (\d{3}:\d+) (\d{3}:\d+) (\d{3}:\d+) (-|[0-9a-f]+) (\d+) (\d+) (\d+)$/.exec(answer);
    if (!m) throw new Error(`not a step answer: ${answer}`);
    return {
      line: answer,
      motors: m.slice(1, 4),
      tx: m[4] === '-' ? '' : Buffer.from(m[4], 'hex').toString('latin1'),
      resets: Number(m[5]),
      erases: Number(m[6]),
      programs: Number(m[7]),
    };
  }

  async quit() {
    this.child.stdin.end('quit\n');
    return this.exit;
  }
}
