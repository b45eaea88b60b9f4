// exid — data that flows between stages: trajectory samples, recorded or simulated datasets,
// observation rows. Columns follow docs/conventions.md §1; all SI.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "exid/export.hpp"
#include "exid/json.hpp"

namespace exid {

/// q, qd, qdd at sample times (a trajectory), K x n each, measured coordinates.
struct EXID_API Samples {
  Eigen::VectorXd t;  // [s]
  Eigen::MatrixXd q, qd, qdd;
  /// Floating-base robots only (else empty): K x 9 base motion per sample, omega alpha f in the
  /// base frame (exid/floating_base.hpp; docs/conventions.md, "Floating base").
  Eigen::MatrixXd base;
  int size() const { return static_cast<int>(t.size()); }
  int dof() const { return static_cast<int>(q.cols()); }
};

struct Dataset;

/// The samples of a dataset too long to hold, read in consecutive chunks (a recording streamed
/// from its file). A pass reads every sample once, in order; rewind() starts another. Reading may
/// throw exid::Error (a bad value found in the file), naming the file and the line.
class EXID_API DatasetStream {
 public:
  virtual ~DatasetStream() = default;
  virtual int size() const = 0;  // samples in a pass
  virtual int dof() const = 0;
  virtual bool hasVelocity() const = 0;
  virtual bool hasAcceleration() const = 0;
  virtual bool hasTorque() const = 0;
  virtual bool hasWrench() const = 0;
  virtual double tFirst() const = 0;  // [s] time of the first and the last sample
  virtual double tLast() const = 0;
  /// Starts a pass at sample 0.
  virtual void rewind() = 0;
  /// The next min(count, left) samples of the pass into *chunk (t, q, ... resized; source set,
  /// meta left as it is). Returns how many: 0 at the end of the pass.
  virtual int read(int count, Dataset* chunk) = 0;
  /// What produced the data (as Dataset::meta); statistics over every sample (e.g. a
  /// recording's duplicate rows) are in it once a whole pass has been read.
  virtual Json meta() const = 0;
  /// Whether a whole pass has been read (meta() is then complete).
  virtual bool passed() const = 0;
  /// Keep every stride-th sample (0, stride, 2 stride, ...) of the first whole pass, for
  /// checks that look at a subset (exid inspect). Call before the first read.
  virtual void collectEvery(int stride) = 0;
  /// Those samples, once a whole pass has been read (empty before).
  virtual const Dataset& collected() const = 0;
  /// The sampling rate 1 / median(dt) of a pass's time stamps and *jitter = max |dt - median| /
  /// median, exactly as exid::samplingRate computes them on the t of a whole pass, when the
  /// stream knows them without a pass (a recording's scan of its time stamps); false otherwise
  /// (exid::samplingRate(const Dataset&) then reads a pass).
  virtual bool samplingRate(double* /*fs_hz*/, double* /*jitter*/) const { return false; }

  /// A pass read in three steps, so that its costly part (parsing) runs on the caller's
  /// threads: fetch() takes the next min(count, left) samples of the pass in order, in a raw
  /// form (a file's bytes), cheaply; decode() turns a fetched piece into samples (t, q, ...,
  /// source; meta left as it is) and may run on any thread, beside other decode() calls and
  /// beside fetch(); settle() takes each decoded piece back in the order of fetch() (the pass's
  /// statistics, collectEvery), one at a time, possibly beside fetch() of later pieces (a
  /// stream keeps the state of the two apart).
  /// decode() throws exid::Error as read() does. A stream that does not split its reading returns
  /// nullptr from fetch() (read() then).
  struct Piece {
    virtual ~Piece() = default;
    int count = 0;  // samples
  };
  virtual std::unique_ptr<Piece> fetch(int /*count*/) { return nullptr; }
  virtual void decode(Piece& /*piece*/, Dataset* /*chunk*/) const {}
  virtual void settle(const Piece& /*piece*/, const Dataset& /*chunk*/) {}
};

/// A rigid load's mass properties in the sensor frame (a simulation's payload).
struct EXID_API LoadMass {
  double mass_kg = 0.0;
  Eigen::Vector3d com_m = Eigen::Vector3d::Zero();              // centre of mass
  Eigen::Matrix3d inertia_com_kg_m2 = Eigen::Matrix3d::Zero();  // about the centre of mass
  bool empty() const { return mass_kg == 0.0 && inertia_com_kg_m2.isZero(0.0); }
};

/// What a simulation's plant held beyond the robot's own parameters: the truth a simulated
/// study is judged against (ObservationModel::fullTruth). Per-drive values hold one value (every
/// drive) or one per drive; empty: none.
struct EXID_API PlantTruth {
  bool drive_terms = true;                     // false: the plant had no drive inertia or friction
  LoadMass payload;                            // carried at the sensor (empty: none)
  std::vector<double> coulomb_negative_Nm;     // Coulomb level for qd < 0 (asymmetric)
  std::vector<double> stribeck_Nm;             // Stribeck amplitude
  std::vector<double> coulomb_load_Nm_per_Nm;  // load-dependent Coulomb friction
  std::vector<double> recorded_torque_gain;    // recorded torque = gain x the drive's torque
  std::vector<double> drive_torque_gain;       // the drive's torque = gain x commanded
};

/// One recording among the several a dataset is made of (DatasetFacts::parts).
struct EXID_API DatasetPart {
  double t_from_s = 0.0;  // [s] the time of its first sample on the dataset's time axis
  std::string source;     // the file or folder it was read from
};

/// What an experiment tells the models and estimators about its dataset, typed (Dataset::meta
/// describes it for people: files, counts, warnings; code reads these).
struct EXID_API DatasetFacts {
  /// Two or more: the dataset is several recordings one after the other, part i holding the
  /// samples from parts[i].t_from_s up to the next part's (times survive slices, windows and
  /// subsampling, indices would not). Nothing may be filtered, differentiated, integrated,
  /// interpolated or simulated across a boundary: the step from one part's last sample to the
  /// next one's first is not a time step of the robot (partRanges gives each part's samples).
  /// Empty: one recording.
  std::vector<DatasetPart> parts;
  /// Set: simulated data, with the plant's truth (the runner compares the estimate with it).
  std::optional<PlantTruth> simulated;
  /// Set: the samples from this time on carry a known payload (experiment csv, payload_file):
  /// the reference of drive gains (model differential, drive_gains).
  std::optional<double> payload_part_from_t_s;
};

/// The facts as summary.json's experiment.meta shows them (keys simulated, payload,
/// drive_terms, the per-drive values, payload_part_from_t_s), written into *meta.
EXID_API void describeFacts(const DatasetFacts& f, Json* meta);

/// A recorded or simulated experiment. Absent signals are empty matrices (0 columns).
/// A streamed dataset (`stream` set) holds no samples itself: its matrices are empty and its
/// samples are read through the stream (materialize() reads them all into memory).
struct EXID_API Dataset {
  Eigen::VectorXd t;           // [s], strictly increasing
  Eigen::MatrixXd q, qd, qdd;  // K x n, measured coordinates [rad or m, /s, /s^2]
  Eigen::MatrixXd tau;         // K x n [N m or N]
  Eigen::MatrixXd wrench;      // K x 6 fx fy fz mx my mz, sensor frame [N, N m]
  /// Floating-base robots only (else empty; docs/conventions.md, "Floating base"):
  /// base     K x 9: omega_x..z [rad/s], alpha_x..z [rad/s^2], f_x..z [m/s^2] (the base
  ///          origin's specific force a - g), all in the base frame;
  /// contact  K x 6C: the wrenches of the C declared contacts, each fx fy fz [N] mx my mz [N m]
  ///          in its sensor frame, exerted by the environment on the robot (the model's
  ///          `contacts` say which body and frame; contact c is columns 6c .. 6c+5).
  Eigen::MatrixXd base;
  Eigen::MatrixXd contact;
  std::string source;          // file or generator, for messages
  Json meta = Json::object();  // what produced it (noise, seed, dropped rows, ...), for people
  DatasetFacts facts;          // what the models and estimators are told, typed

  std::shared_ptr<DatasetStream> stream;  // set: the samples are read through it

  bool streamed() const { return stream != nullptr; }
  int size() const { return stream ? stream->size() : static_cast<int>(t.size()); }
  int dof() const { return stream ? stream->dof() : static_cast<int>(q.cols()); }
  bool hasVelocity() const { return stream ? stream->hasVelocity() : qd.cols() > 0; }
  bool hasAcceleration() const { return stream ? stream->hasAcceleration() : qdd.cols() > 0; }
  bool hasTorque() const { return stream ? stream->hasTorque() : tau.cols() > 0; }
  bool hasWrench() const { return stream ? stream->hasWrench() : wrench.cols() > 0; }
  /// Floating-base signals (never streamed: a stream carries none).
  bool hasBase() const { return !stream && base.cols() > 0; }
  bool hasContact() const { return !stream && contact.cols() > 0; }
  double tFirst() const { return stream ? stream->tFirst() : t(0); }
  double tLast() const { return stream ? stream->tLast() : t(t.size() - 1); }
  /// Samples view (copies q, qd, qdd; a dataset in memory).
  Samples samples() const {
    Samples s{t, q, qd, qdd, base};
    return s;
  }
};

/// The samples [begin, end) of one part among a dataset's times, and which part it is (an index
/// into DatasetFacts::parts; 0 for a dataset of one recording).
struct EXID_API PartRange {
  int begin = 0, end = 0;
  int part = 0;
};
/// The samples of each part (DatasetFacts::parts) among the times t (a dataset's, or a slice's
/// or a subsample's of it), in order; parts without a sample in t are left out. One range
/// [0, t.size()) when facts has fewer than two parts.
EXID_API std::vector<PartRange> partRanges(const Eigen::VectorXd& t, const DatasetFacts& facts);
/// An exid::Error starting with `who` when d holds several recordings (DatasetFacts::parts),
/// naming them and saying `why` (the caller needs one continuous recording; what to do instead).
EXID_API void requireOnePart(const Dataset& d, const std::string& who, const std::string& why);
/// Several recordings in memory as the parts of one dataset, in the order given: the same joints
/// and signals in each (else an exid::Error starting with `who`, naming the part). Part i's
/// times are shifted so that it starts one median time step (of part i - 1) after part i - 1
/// ends: t stays strictly increasing and the shift of each part is in meta.parts. Its meta:
/// `file` and `source` list the parts' sources; `samples` and `signals`; `warnings` and `notes`
/// are the parts' own, each naming its part; `parts` holds each part's source, samples, time
/// range, shift and own meta. A part must not be simulated, carry a payload part or be made of
/// parts itself. A single dataset is returned as it is.
EXID_API Dataset joinParts(std::vector<Dataset> parts, const std::string& who);

/// Samples [begin, end) of a dataset in memory (source, meta and facts kept).
EXID_API Dataset sliceDataset(const Dataset& d, int begin, int end);
/// Every signal of d (in memory, at least two samples) linearly interpolated onto the uniform
/// grid t0 + m / rate_hz, m = 0 .. floor(span * rate_hz); source, meta and facts kept. `who` starts
/// the messages (e.g. "experiment 'csv': file.csv"): fewer than two samples, or a grid of fewer
/// than 2 or more than 1e8 samples, is an exid::Error.
EXID_API Dataset resampleUniform(const Dataset& d, double rate_hz, const std::string& who);
/// A dataset in memory: d itself, or every sample of its stream read in one pass (meta then
/// the stream's, complete; facts kept).
EXID_API Dataset materialize(const Dataset& d);

/// Consecutive spans of a dataset, in memory or streamed, asked for in order: span(b, e) with b
/// and e never below the previous call's. A stream is read once, keeping only the samples
/// between the lowest begin still to come and the highest end asked for.
class EXID_API SampleWindow {
 public:
  explicit SampleWindow(const Dataset& d);
  /// Samples [begin, end) (source, meta and facts of the dataset).
  Dataset span(int begin, int end);

 private:
  const Dataset& d_;
  Dataset buf_;  // samples [buf_begin_, buf_begin_ + buf_.size()) of a stream
  int buf_begin_ = 0;
  bool started_ = false;
};

/// Observation rows of a model: W * theta ~= y. Columns are BASE parameters of the model.
struct EXID_API Rows {
  Eigen::MatrixXd W;
  Eigen::VectorXd y;
  std::vector<int> equation;  // per row: which equation it is (joint index, wrench component,
                              // window), so estimators can weight per equation
  int numEquations = 1;       // distinct values in `equation`
  std::vector<double> t;      // per row: time of its sample [s] (a window: its end); may be empty
  std::vector<std::string> equation_names;  // per equation, e.g. "tau joint 2 (shoulder)"
  // per row: the recorded torque a torque column of the row (exid::torqueColumnKind: FcL) holds,
  // where y is not that torque (a floating base's joint rows: y = tau + J^T w); empty: y is it
  std::vector<double> torque;
};

}  // namespace exid
