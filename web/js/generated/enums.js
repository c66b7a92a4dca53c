// The service's closed sets, from its OpenAPI document (/openapi.json). Written by
// `python -m server.schemas.web_enums`; do not edit: a test fails while this differs from what
// that command writes, or while a page names a value (RunStatus.running) that is not here.

/** RunPublic.status */
export const RunStatus = Object.freeze({
  created: "created",
  running: "running",
  paused: "paused",
  finished: "finished",
  stopped: "stopped",
  interrupted: "interrupted",
  failed: "failed",
});

/** RunPublic.mode */
export const RunMode = Object.freeze({
  fast: "fast",
  realtime: "realtime",
});

/** RunCreate.condition */
export const Condition = Object.freeze({
  innate: "innate",
  delayed: "delayed",
  dp: "dp",
  dp_rare: "dp-rare",
  rp: "rp",
  trainer: "trainer",
  kp: "kp",
  kp_punished: "kp-punished",
  sonar: "sonar",
  expert: "expert",
  reflexes: "reflexes",
  unaware: "unaware",
  kp_signal: "kp-signal",
  beacon: "beacon",
  beacon_reflexes: "beacon-reflexes",
});

/** EpisodePublic.outcome */
export const Outcome = Object.freeze({
  success: "success",
  failure: "failure",
});

/** EpisodePublic.cause */
export const Cause = Object.freeze({
  wall_collision: "wall_collision",
  obstacle_collision: "obstacle_collision",
  signal_violation: "signal_violation",
  timeout: "timeout",
});

/** AssociationPublic.source */
export const AssociationSource = Object.freeze({
  innate: "innate",
  dp: "dp",
  learned: "learned",
  kp: "kp",
  expert: "expert",
  designed: "designed",
});

/** AssociationEvent.change */
export const AssociationChange = Object.freeze({
  promoted: "promoted",
  demoted: "demoted",
});

/** RewardPublic.source */
export const RewardSource = Object.freeze({
  trainer: "trainer",
  program: "program",
  task: "task",
});

/** StimulusPublic.level */
export const StimulusLevel = Object.freeze({
  low: "low",
  high: "high",
});

/** TickEvent.lamp */
export const Lamp = Object.freeze({
  none: "none",
  red: "red",
  yellow: "yellow",
  green: "green",
});

/** TickEvent.how */
export const How = Object.freeze({
  released: "released",
  default: "default",
  explored: "explored",
  continued: "continued",
  commanded: "commanded",
});

/** KpProvenancePublic.resolution */
export const KpResolution = Object.freeze({
  snapped: "snapped",
  synthesized: "synthesized",
  reused: "reused",
});
