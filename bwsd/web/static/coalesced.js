// @ts-check
// One run of some work at a time: asking while it runs asks for one more run after it.

export class Coalesced {
  /**
   * @param {() => Promise<void>} work the async work
   * @param {object} [options]
   * @param {() => void} [options.after] called once the runs are over, whatever happened
   * @param {(error: unknown) => void} [options.onError] called with an error a run threw
   *   (the daemon could not be reached)
   */
  constructor(work, { after = () => {}, onError = () => {} } = {}) {
    this.work = work;
    this.after = after;
    this.onError = onError;
    /** @type {Promise<void> | null} the runs under way, if any */
    this.running = null;
    this.again = false;
  }

  run() {
    if (this.running) {
      this.again = true;
      return this.running;
    }
    this.running = (async () => {
      try {
        do {
          this.again = false;
          await this.work();
        } while (this.again);
      } catch (error) {
        this.onError(error);
      } finally {
        this.running = null;
        this.after();
      }
    })();
    return this.running;
  }
}
