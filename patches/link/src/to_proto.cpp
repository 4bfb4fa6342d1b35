#include "ruffini/link/to_proto.h"

namespace ruffini::link {

void ToProto(const Message& m, const std::string& patch_id, std::uint64_t seq, v1::PatchMessage& out) {
  out.Clear();
  out.set_patch_id(patch_id);
  out.set_seq(seq);
  out.set_interrogator_serial(m.serial);
  out.set_t_ns(m.t_ns);
  out.set_decoder_t_ns(m.decoder_t_ns);
  switch (m.kind) {
    case Message::Kind::kContact: {
      const Contact& c = m.contact;
      v1::PatchContact* p = out.mutable_contact();
      p->set_force_n(c.force_n);
      p->set_force_sd_n(c.force_sd_n);
      p->set_located(c.located);
      p->set_y_mm(c.y_mm);
      p->set_r_deg(c.r_deg);
      p->set_cov_yy_mm2(c.cov_yy_mm2);
      p->set_cov_yr_mm2(c.cov_yr_mm2);
      p->set_cov_rr_mm2(c.cov_rr_mm2);
      p->set_confidence(c.confidence);
      p->set_onset(c.onset);
      p->set_released(c.released);
      p->set_common_mode_pm(c.common_mode_pm);
      p->set_missing_peaks(c.missing);
      p->set_uncertainty_calibrated(c.uncertainty);
      p->set_over_range(c.over_range);
      p->set_force_lower_bound_n(c.force_lower_bound_n);
      p->set_multiple(c.multiple);
      p->set_faint(c.faint);
      break;
    }
    case Message::Kind::kHeartbeat: {
      const Health& h = m.health;
      v1::Heartbeat* p = out.mutable_heartbeat();
      p->set_healthy(h.healthy);
      p->set_active_fault(static_cast<v1::PatchFaultCode>(h.active_fault));
      p->set_frames(h.frames);
      p->set_valid_frames(h.valid_frames);
      p->set_serial_gaps(h.serial_gaps);
      p->set_frames_lost(h.frames_lost);
      for (std::size_t i = 1; i < h.decode_rejected.size(); ++i) {
        if (h.decode_rejected[i] == 0) continue;
        auto* r = p->add_rejected();
        r->set_reason(static_cast<v1::FrameRejectReason>(RejectCode(static_cast<decode::Reason>(i))));
        r->set_frames(h.decode_rejected[i]);
      }
      for (std::size_t i = 1; i < h.stream_rejected.size(); ++i) {
        if (h.stream_rejected[i] == 0) continue;
        auto* r = p->add_rejected();
        r->set_reason(static_cast<v1::FrameRejectReason>(RejectCode(static_cast<ingest::Reason>(i))));
        r->set_frames(h.stream_rejected[i]);
      }
      p->set_onsets(h.onsets);
      p->set_in_contact(h.in_contact);
      p->set_baseline_state(static_cast<v1::BaselineState>(h.baseline));
      p->set_drift_pm(h.drift_pm);
      p->set_common_mode_pm(h.common_mode_pm);
      p->set_baseline_frozen_s(h.frozen_s);
      p->set_messages_dropped(h.messages_dropped);
      break;
    }
    case Message::Kind::kFault: {
      v1::PatchFault* p = out.mutable_fault();
      p->set_code(static_cast<v1::PatchFaultCode>(m.fault.code));
      p->set_reason(static_cast<v1::FrameRejectReason>(m.fault.reason));
      p->set_message(m.fault.text.data());
      break;
    }
    case Message::Kind::kRetare: {
      v1::RetareResult* p = out.mutable_retare_result();
      p->set_request_id(m.retare.request_id);
      p->set_outcome(static_cast<v1::RetareOutcome>(static_cast<int>(m.retare.outcome) + 1));
      p->set_force_n(m.retare.force_n);
      p->set_y_mm(m.retare.y_mm);
      p->set_r_deg(m.retare.r_deg);
      p->set_motion_pm(m.retare.motion_pm);
      p->set_min_force_n(m.retare.min_force_n);
      break;
    }
  }
}

}  // namespace ruffini::link
