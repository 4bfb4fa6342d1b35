#pragma once
// ruffini::ProgressBar — a minimal terminal progress bar for long batch jobs.
//
// Hand-written on purpose: Debian 12 ships no maintained C++ progress-bar package in the project's
// allowed dependency set (indicators, tqdm-cpp, ... are not packaged), and this is ~60 lines of logic.
//
// On a TTY: one line redrawn with '\r', at most ~10x per second:
//   label [#####...............]  42%  1.2M/2.7M  3.4M/s  ETA 0:02
// Not a TTY (CI logs): one plain line per 10 % step (a jump over several steps prints one line), plus the
// Finish line; with an unknown total (0) only the Finish line. Not thread-safe: update from one thread.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>

namespace ruffini {

class ProgressBar {
 public:
  ProgressBar(std::string label, std::uint64_t total, std::FILE* out = stderr)
      : label_(std::move(label)),
        total_(total),
        out_(out),
        tty_(out != nullptr && isatty(fileno(out)) != 0),
        start_(Clock::now()),
        last_check_(start_),
        last_draw_(start_),
        next_step_done_(total == 0 ? kNever : StepDone(1)) {}
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;
  ~ProgressBar() { Finish(); }

  // Cheap enough for every iteration: off a TTY one comparison; on a TTY the clock is read only every
  // stride_ calls, with stride_ adapted so that happens every ~1-20 ms whatever the iteration rate.
  void Update(std::uint64_t done) {
    done_ = done;
    if (finished_ || out_ == nullptr) return;
    if (!tty_) {
      if (done < next_step_done_ || step_ >= 10) return;
      while (step_ < 10 && StepDone(step_ + 1) <= done) ++step_;
      next_step_done_ = step_ < 10 ? StepDone(step_ + 1) : kNever;
      Emit(label_ + "  " + std::to_string(step_ * 10) + "%" + Stats(Clock::now()), true);
      return;
    }
    if (++calls_ < stride_) return;
    calls_ = 0;
    const auto now = Clock::now();
    const auto since = now - last_check_;
    last_check_ = now;
    if (since < std::chrono::milliseconds(1) && stride_ < (1u << 16)) stride_ *= 2;
    else if (since > std::chrono::milliseconds(20) && stride_ > 1) stride_ /= 2;
    if (now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    Emit(Bar() + Stats(now), false);
  }

  // A short note shown after the statistics on every line from now on (e.g. "loss 0.124").
  void SetNote(std::string note) { note_ = std::move(note); }

  // Final line with elapsed time and mean rate. Idempotent; the destructor calls it.
  void Finish() {
    if (finished_ || out_ == nullptr) return;
    finished_ = true;
    const double secs = std::chrono::duration<double>(Clock::now() - start_).count();
    std::string line = label_ + "  done: " + Count(static_cast<double>(done_)) +
                       (total_ ? "/" + Count(static_cast<double>(total_)) : "") + " in " + Elapsed(secs) + ", " +
                       Count(secs > 0.0 ? static_cast<double>(done_) / secs : 0.0, true) + "/s";
    if (!note_.empty()) line += "  " + note_;
    Emit(line, true);
  }

 private:
  using Clock = std::chrono::steady_clock;
  static constexpr std::uint64_t kNever = std::numeric_limits<std::uint64_t>::max();

  // Smallest done with done * 10 >= total * k, without overflow.
  [[nodiscard]] std::uint64_t StepDone(unsigned k) const {
    return total_ / 10 * k + (total_ % 10 * k + 9) / 10;
  }
  [[nodiscard]] double Fraction() const {
    return total_ ? std::min(1.0, static_cast<double>(done_) / static_cast<double>(total_)) : 0.0;
  }
  [[nodiscard]] std::string Bar() const {
    if (!total_) return label_;
    const auto filled = static_cast<std::size_t>(Fraction() * 20.0);
    char pct[8];
    std::snprintf(pct, sizeof pct, "%3d%%", static_cast<int>(Fraction() * 100.0));
    return label_ + " [" + std::string(filled, '#') + std::string(20 - filled, '.') + "] " + pct;
  }
  [[nodiscard]] std::string Stats(Clock::time_point now) const {
    const double secs = std::chrono::duration<double>(now - start_).count();
    const double rate = secs > 0.0 ? static_cast<double>(done_) / secs : 0.0;
    std::string s = "  " + Count(static_cast<double>(done_)) + (total_ ? "/" + Count(static_cast<double>(total_)) : "") +
                    "  " + Count(rate, true) + "/s";
    const std::string note = note_.empty() ? "" : "  " + note_;
    if (!total_) return s + "  " + Elapsed(secs) + note;
    const double left = static_cast<double>(total_ - std::min(done_, total_));
    return s + "  ETA " + (left == 0.0 ? "0:00" : rate > 0.0 ? Hms(left / rate) : "--:--") + note;
  }
  static std::string Count(double v, bool fractional = false) {
    static constexpr char kUnit[] = " kMGTPE";
    int u = 0;
    while (v >= 999.95 && u < 6) v /= 1000.0, ++u;
    char buf[32];
    if (u == 0) std::snprintf(buf, sizeof buf, fractional && v < 100.0 ? "%.1f" : "%.0f", v);
    else std::snprintf(buf, sizeof buf, "%.1f%c", v, kUnit[u]);
    return buf;
  }
  static std::string Hms(double secs) {  // m:ss or h:mm:ss
    if (!(secs < 360000.0)) return "--:--";
    const auto t = static_cast<long>(secs + 0.5);
    char buf[32];
    if (t >= 3600) std::snprintf(buf, sizeof buf, "%ld:%02ld:%02ld", t / 3600, t / 60 % 60, t % 60);
    else std::snprintf(buf, sizeof buf, "%ld:%02ld", t / 60, t % 60);
    return buf;
  }
  static std::string Elapsed(double secs) {
    if (secs >= 60.0) return Hms(secs);
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.1fs", secs);
    return buf;
  }
  // On a TTY: '\r' + text, padded with spaces over the leftovers of a longer previous line.
  void Emit(const std::string& text, bool newline) {
    std::string line = tty_ ? "\r" + text : text;
    if (tty_ && text.size() < last_len_) line.append(last_len_ - text.size(), ' ');
    last_len_ = newline ? 0 : text.size();
    if (newline) line += '\n';
    std::fputs(line.c_str(), out_);
    std::fflush(out_);
  }

  std::string label_;
  std::string note_;
  std::uint64_t total_;
  std::FILE* out_;
  bool tty_;
  Clock::time_point start_, last_check_, last_draw_;
  std::uint64_t next_step_done_;
  std::uint64_t done_ = 0;
  unsigned step_ = 0, calls_ = 0, stride_ = 1;
  std::size_t last_len_ = 0;
  bool finished_ = false;
};

}  // namespace ruffini
