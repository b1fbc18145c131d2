"""The one vocabulary of event and health fields.

Anomaly events (``anomalies`` topic, events JSON) and health statuses (``/diagnostics``)
carry these keys. A key with a unit ends in it (``_s`` seconds, ``_nm`` newton metres,
``_nms`` newton metre seconds per radian, ``_rad_s`` radians per second). The events JSON
uses the same names, except that the estimated change time and row are ``time`` and
``index`` as the events-file contract fixes them.
"""

DETECTOR = 'detector'
COMPONENT = 'component'
KIND = 'kind'
CHANGE_TIME = 'change_time_s'
CHANGE_INDEX = 'change_index'
DECLARATION_TIME = 'declaration_time_s'
DECLARATION_INDEX = 'declaration_index'
P_VALUE = 'p_value'
REVISION = 'revision'
DELTA_DRY = 'delta_dry_nm'
DELTA_VISCOUS = 'delta_viscous_nms'
NOISE_STD = 'noise_std_nm'

# Event kinds, by detector.
FRICTION_KINDS = ('dry', 'viscous', 'both')
GYRO_KINDS = ('drift', 'bias')
WINDOW_KINDS = ('dry', 'viscous', 'fss1', 'fss2')
# A detector node's calibration in force changed at run time (level OK, not an alarm).
CALIBRATION_KIND = 'calibration_changed'

# Names of fields in the events JSON that differ from the KeyValue key.
JSON_NAME = {CHANGE_TIME: 'time', CHANGE_INDEX: 'index',
             DECLARATION_TIME: 'declared_time', DECLARATION_INDEX: 'declared_index'}

# LLR friction detector (llr-realtime paper): extra event details.
Z_DRY = 'z_dry'
Z_VISCOUS = 'z_viscous'
KIND_CONFIRMED = 'kind_confirmed'   # False: the data cannot tell dry from viscous yet
ARGMIN_INDEX = 'argmin_index'
LOG10_P_VALUE = 'log10_p_value'
KIND_GUESS = 'kind_guess'           # better single kind when kind is 'undecided'
KIND_SHAPE = 'kind_shape'           # 'step', or 'ramp' when a ramp model named the kind
DETECTABLE_DRY = 'detectable_dry_nm'          # dry step found with 90 % power after
DETECTABLE_VISCOUS = 'detectable_viscous_nms'  # the change (inf: not separable)
KIND_REASON = 'kind_reason'         # why the kind is 'undecided' (only then)
FINAL = 'final'                     # the end-of-record categorisation (only then, True)
FINAL_SAMPLES = 'final_samples'     # samples after the change it used (only then)
AFTER_GAP = 'after_gap_s'           # a change in a gap: time since the last sample before it

# Calibration in force (detector nodes' ``calibration_file``): event and health fields.
CALIBRATION_FILE = 'calibration_file'
CALIBRATION_SHA256 = 'calibration_sha256'
CALIBRATION_LOADED = 'calibration_loaded_unix_s'
CALIBRATION_WHEELS = 'calibration_wheels'
CALIBRATION_LOADS = 'calibration_loads'
PREVIOUS_CALIBRATION = 'previous_calibration_file'

# FSS window diagnoser (physics-informed FSS paper): window and extracted components.
WINDOW_START = 'window_start_s'
WINDOW_END = 'window_end_s'
BASE_DRY = 'base_dry_nm'
VISCOUS = 'viscous_nms'
SVM_DECISION = 'svm_decision'
# A window diagnoser filling its first window: samples still missing (level STALE, shown
# as waiting: not examined yet, not a lost input).
WAITING_SAMPLES = 'waiting_samples'

# VSADC gyro classifier (vsadc-gyro-drift paper): event details and axis health.
GYRO_STATES = ('healthy', 'drift', 'bias')   # labels 0, 1, 2; events carry the new one
PREVIOUS_KIND = 'previous_kind'
STATE = 'state'
READY = 'ready'
DISTANCE = 'distance_rad_s'
DISTANCE_SIGMA = 'distance_sigma_rad_s'
SIGMA_LIM1 = 'sigma_lim1_rad_s'
SIGMA_LIM2 = 'sigma_lim2_rad_s'

# Counters of bad input (every detector's ``counters``, node health): one name per reason.
NON_FINITE = 'non_finite'                     # NaN, Inf or not a number: time or value
NON_INCREASING_TIME = 'non_increasing_time'   # a stamp not after the last accepted one
OUT_OF_RANGE = 'out_of_range'                 # a value beyond the detector's bound
ILL_CONDITIONED = 'ill_conditioned'           # a test skipped: the data cannot decide it
