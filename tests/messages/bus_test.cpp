// Unit tests of the typed bus and the protocol endpoints on memq:// (one process, no network).
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <set>

#include "messages/bus.hpp"
#include "messages/protocol.hpp"

using namespace demfdm;

namespace {
std::shared_ptr<lcm::LCM> memq() {
  auto l = std::make_shared<lcm::LCM>("memq://");
  EXPECT_TRUE(l->good());
  return l;
}
demfdm::report_t report(double v) {
  demfdm::report_t r{};
  r.header.step = 3;
  r.n_values = 1;
  r.names = {"x"};
  r.values = {v};
  return r;
}
}  // namespace

TEST(Messages, EncodeDecodeRoundTripAndFingerprintsDiffer) {
  auto r = report(1.5);
  r.text = "hello";
  std::vector<std::uint8_t> buf(r.getEncodedSize());
  ASSERT_EQ(r.encode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  demfdm::report_t back;
  ASSERT_EQ(back.decode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  EXPECT_EQ(back.values[0], 1.5);
  EXPECT_EQ(back.text, "hello");
  auto fp = bus::compiled_fingerprints();
  std::set<std::int64_t> unique;
  for (auto& f : fp) unique.insert(f.hash);
  EXPECT_EQ(unique.size(), fp.size()) << "every message type must have its own fingerprint";
}

TEST(Bus, TypedPublishSubscribeFillsHeader) {
  auto l = memq();
  bus::Bus a(l, 7, "dem"), b(l, 7, "coordinator");
  std::vector<demfdm::report_t> got;
  b.subscribe<demfdm::report_t>("R", [&](const demfdm::report_t& r) { got.push_back(r); });
  auto r = report(2.0);
  auto seq1 = a.publish("R", r);
  auto seq2 = a.publish("R", r);
  b.pump(0.1);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].header.sender, "dem");
  EXPECT_EQ(got[0].header.run_id, 7);
  EXPECT_EQ(got[0].header.msg_type, demfdm::msg_types_t::MSG_REPORT);
  EXPECT_EQ(got[0].header.seq, seq1);
  EXPECT_EQ(got[1].header.seq, seq2);
  EXPECT_EQ(seq2, seq1 + 1);
}

TEST(Bus, RejectsForeignRunOwnEchoAndDuplicates) {
  auto l = memq();
  bus::Bus a(l, 7, "dem"), other_run(l, 8, "dem"), b(l, 7, "coordinator");
  int n = 0;
  b.subscribe<demfdm::report_t>("R", [&](const demfdm::report_t&) { ++n; });
  a.subscribe<demfdm::report_t>("R", [&](const demfdm::report_t&) { ADD_FAILURE() << "own message delivered"; });
  auto r = report(1);
  a.publish("R", r);
  a.republish("R", r);  // same seq: a duplicate
  other_run.publish("R", r);
  b.pump(0.1);
  EXPECT_EQ(n, 1);
  auto s = b.stats();
  EXPECT_EQ(s.duplicates, 1);
  EXPECT_EQ(s.foreign_run, 1);
  EXPECT_GE(a.stats().own_echo, 1);
}

TEST(Bus, CorruptMessageIsCountedNotThrown) {
  auto l = memq();
  bus::Bus b(l, 7, "coordinator");
  int n = 0;
  b.subscribe<demfdm::report_t>("R", [&](const demfdm::report_t&) { ++n; });
  // A report whose n_values length field is -1: lcm-gen's decode() would throw inside C code.
  auto r = report(1);
  r.header.run_id = 7;
  r.header.sender = "dem";
  r.header.msg_type = demfdm::msg_types_t::MSG_REPORT;
  std::vector<std::uint8_t> buf(r.getEncodedSize());
  r.encode(buf.data(), 0, static_cast<int>(buf.size()));
  std::vector<std::uint8_t> junk(buf.begin(), buf.begin() + 20);  // truncated
  l->publish("R", junk.data(), static_cast<unsigned>(junk.size()));
  // And a message of another type on the channel.
  demfdm::heartbeat_t hb{};
  bus::Bus a(l, 7, "dem");
  a.publish("R", hb);
  EXPECT_NO_THROW(b.pump(0.1));
  EXPECT_EQ(n, 0);
  EXPECT_EQ(b.stats().decode_errors + b.stats().wrong_type, 2);
}

TEST(Bus, HandlerErrorIsRethrownFromPump) {
  auto l = memq();
  bus::Bus a(l, 7, "dem"), b(l, 7, "coordinator");
  b.subscribe<demfdm::report_t>("R", [&](const demfdm::report_t&) { throw std::runtime_error("handler says no"); });
  auto r = report(1);
  a.publish("R", r);
  EXPECT_THROW(
      {
        try {
          b.pump(0.1);
        } catch (const std::runtime_error& e) {
          EXPECT_STREQ(e.what(), "handler says no");
          throw;
        }
      },
      std::runtime_error);
}

TEST(Bus, FaultInjectionDropsAndDuplicates) {
  setenv("DEMFDM_FAULT", "drop:R:2,dup:R:3", 1);
  auto l = memq();
  bus::Bus a(l, 7, "dem");
  unsetenv("DEMFDM_FAULT");
  bus::Bus b(l, 7, "coordinator");
  std::vector<double> got;
  b.subscribe<demfdm::report_t>("R", [&](const demfdm::report_t& r) { got.push_back(r.values[0]); });
  for (int i = 1; i <= 4; ++i) {
    auto r = report(i);
    a.publish("R", r);
  }
  b.pump(0.1);
  EXPECT_EQ(got, (std::vector<double>{1, 3, 4}));  // 2 dropped; the duplicate of 3 filtered
  EXPECT_EQ(b.stats().duplicates, 1);
  EXPECT_EQ(a.stats().injected_drops, 1);
  setenv("DEMFDM_FAULT", "explode:R", 1);
  EXPECT_THROW(bus::Bus(l, 7, "x"), bus::BusError);
  unsetenv("DEMFDM_FAULT");
}

TEST(Bus, UrlResolution) {
  unsetenv("LCM_DEFAULT_URL");
  EXPECT_EQ(bus::resolve_url("udpm://239.255.76.67:7000?ttl=0"), "udpm://239.255.76.67:7000?ttl=0&recv_buf_size=4194304");
  EXPECT_EQ(bus::resolve_url("udpm://239.255.76.67:7000"), "udpm://239.255.76.67:7000?recv_buf_size=4194304");
  EXPECT_EQ(bus::resolve_url("memq://"), "memq://");
  setenv("LCM_DEFAULT_URL", "memq://", 1);
  EXPECT_EQ(bus::resolve_url(""), "memq://");
  unsetenv("LCM_DEFAULT_URL");
}

TEST(Protocol, ChunksCoverTheRangeOnce) {
  auto c = proto::chunks(2500, 1000);
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c[2].first, 2000u);
  EXPECT_EQ(c[2].second, 500u);
  EXPECT_EQ(proto::chunks(0).size(), 1u);
}

TEST(Protocol, InterfaceDataSurvivesChunkingAndMessagesStaySmall) {
  auto l = memq();
  bus::Bus cb(l, 9, "continuum"), db(l, 9, "dem");
  proto::NodeEndpoint cont(cb, "continuum", "test"), dem(db, "dem", "test");
  // Keep the coordinator "alive" for the endpoints' liveness check.
  bus::Bus coord(l, 9, "coordinator");
  proto::Heartbeat hb(coord, 0.05);
  proto::Kinematics k;
  k.step = 4;
  const std::size_t n = 2345;
  for (std::size_t i = 0; i < 3 * n; ++i) {
    k.positions.push_back(0.001 * static_cast<double>(i));
    k.velocities.push_back(-1.0 * static_cast<double>(i));
  }
  cont.send_kin(k);
  auto got = dem.wait_kin(4);
  EXPECT_EQ(got.positions, k.positions);
  EXPECT_EQ(got.velocities, k.velocities);
  // The largest chunk: 1000 points x 48 B + header.
  demfdm::iface_kin_t m{};
  m.n_points = 1000;
  m.n_coords = 3000;
  m.positions.assign(3000, 1.0);
  m.velocities.assign(3000, 1.0);
  EXPECT_LT(m.getEncodedSize(), 60000);
  // Forces, with the total checked by the receiver side.
  proto::Forces f;
  f.step = 4;
  f.forces.assign(3 * n, 0.5);
  f.stiffness.assign(n, 2.0);
  f.total = {0.5 * n, 0.5 * n, 0.5 * n};
  dem.send_forces(f);
  auto gf = cont.wait_forces(4);
  EXPECT_EQ(gf.forces, f.forces);
  EXPECT_EQ(gf.total, f.total);
}

TEST(Protocol, NonFiniteInterfaceDataStopsTheRunNamingTheSender) {
  auto l = memq();
  bus::Bus cb(l, 9, "continuum"), db(l, 9, "dem"), coord(l, 9, "coordinator");
  proto::Heartbeat hb(coord, 0.05);
  proto::NodeEndpoint cont(cb, "continuum", "test"), dem(db, "dem", "test");
  proto::Kinematics k;
  k.step = 1;
  k.positions = {0, 0, std::nan("")};
  k.velocities = {0, 0, 0};
  cont.send_kin(k);
  try {
    dem.wait_kin(1);
    FAIL() << "expected a ProtocolError";
  } catch (const proto::ProtocolError& e) {
    EXPECT_NE(std::string(e.what()).find("non-finite interface kinematics from continuum at step 1, point row 0"),
              std::string::npos)
        << e.what();
  }
}

TEST(Protocol, LostMessageIsResentAfterNack) {
  setenv("DEMFDM_FAULT", "drop:DEMFDM_IFACE_FORCE:1", 1);
  auto l = memq();
  bus::Bus db(l, 9, "dem");
  unsetenv("DEMFDM_FAULT");
  bus::Bus cb(l, 9, "continuum"), coord(l, 9, "coordinator");
  proto::Heartbeat hb(coord, 0.05);
  proto::NodeEndpoint cont(cb, "continuum", "test"), dem(db, "dem", "test");
  proto::Forces f;
  f.step = 2;
  f.forces = {1, 2, 3};
  f.stiffness = {4};
  dem.send_forces(f);  // dropped
  // The continuum waits, NACKs; whoever pumps dispatches the NACK to the DEM endpoint too.
  auto got = cont.wait_forces(2);
  EXPECT_EQ(got.forces, f.forces);
  EXPECT_GE(cont.nacks_sent(), 1);
  EXPECT_GE(dem.resends(), 1);
}

TEST(Protocol, SilentCoordinatorIsDetected) {
  auto l = memq();
  bus::Bus db(l, 9, "dem");
  proto::Timeouts t;
  t.peer_timeout_s = 0.3;
  proto::NodeEndpoint dem(db, "dem", "test", t);
  auto t0 = std::chrono::steady_clock::now();
  EXPECT_THROW(dem.next_command(), proto::ProtocolError);
  double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(s, 1.0);
}

namespace {
// A node's hello as a fake: lets a test tamper with what the coordinator checks.
demfdm::hello_t fake_hello(std::uint64_t hash) {
  demfdm::hello_t h{};
  h.role = "dem";
  h.solver = "fake";
  h.protocol_version = proto::kProtocolVersion;
  h.scene_hash = static_cast<std::int64_t>(hash);
  for (auto& f : bus::compiled_fingerprints()) {
    h.type_names.push_back(f.name);
    h.fingerprints.push_back(f.hash);
  }
  h.n_types = static_cast<std::int32_t>(h.type_names.size());
  h.pid = 1;
  h.host = "here";
  return h;
}

std::string start_with(std::function<void(demfdm::hello_t&)> tamper) {
  auto l = memq();
  bus::Bus cb(l, 5, "coordinator"), nb(l, 5, "dem");
  proto::Timeouts t;
  t.startup_s = 2.0;
  proto::CoordinatorEndpoint coord(cb, t);
  const std::string text = "[dem]\n";
  // FNV-1a 64 of the text, as config::Scene::hash() computes it.
  std::uint64_t h = 14695981039346656037ull;
  for (unsigned char c : text) h = (h ^ c) * 1099511628211ull;
  // The node answers every scene broadcast with its (tampered) hello.
  nb.subscribe<demfdm::scene_t>(bus::channel::kScene, [&](const demfdm::scene_t&) {
    auto hello = fake_hello(h);
    tamper(hello);
    nb.publish(bus::channel::kHello, hello);
  });
  try {
    coord.start(text, "test.toml", h, {"dem"});
  } catch (const proto::ProtocolError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(Handshake, MatchingHelloIsAccepted) {
  EXPECT_EQ(start_with([](demfdm::hello_t&) {}), "");
}

TEST(Handshake, MismatchesAreRefusedNamingWhatDiffers) {
  auto version = start_with([](demfdm::hello_t& h) { h.protocol_version = 99; });
  EXPECT_NE(version.find("node 'dem' (fake, pid 1 on here) speaks protocol version 99, the coordinator 1"), std::string::npos)
      << version;
  auto hash = start_with([](demfdm::hello_t& h) { h.scene_hash ^= 1; });
  EXPECT_NE(hash.find("received a different scene (hash mismatch)"), std::string::npos) << hash;
  auto fp = start_with([](demfdm::hello_t& h) { h.fingerprints[4] ^= 1; });
  EXPECT_NE(fp.find("different definition of message type report_t (fingerprint mismatch)"), std::string::npos) << fp;
  auto missing = start_with([](demfdm::hello_t& h) {
    h.type_names.pop_back();
    h.fingerprints.pop_back();
    h.n_types -= 1;
  });
  EXPECT_NE(missing.find("does not know message type iface_force_t"), std::string::npos) << missing;
}

// The tee's size guard: the coordinator repeats the scene (here two chunks) every 250 ms until
// the node says hello (here at the 4th broadcast); its traffic log holds each chunk's text once,
// every repeat as a text-less stub on DEMFDM_SCENE_REPEAT (same header, hash and chunk).
TEST(Tee, SceneChunksAreRecordedOncePerProcess) {
  namespace fs = std::filesystem;
  fs::path dir = fs::temp_directory_path() / ("demfdm-tee-scene-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  auto l = memq();
  setenv("DEMFDM_TRAFFIC_DIR", dir.c_str(), 1);
  auto cb = std::make_unique<bus::Bus>(l, 5, "coordinator");
  unsetenv("DEMFDM_TRAFFIC_DIR");
  bus::Bus nb(l, 5, "dem");
  proto::Timeouts t;
  t.startup_s = 5.0;
  std::string text = "[dem]\n";
  while (text.size() < 60000) text += "# a long scene: the size guard of the traffic log\n";
  std::uint64_t h = 14695981039346656037ull;
  for (unsigned char c : text) h = (h ^ c) * 1099511628211ull;
  int broadcasts = 0;
  nb.subscribe<demfdm::scene_t>(bus::channel::kScene, [&](const demfdm::scene_t& s) {
    if (s.chunk_index == 0 && ++broadcasts == 4) {
      auto hello = fake_hello(h);
      nb.publish(bus::channel::kHello, hello);
    }
  });
  {
    proto::CoordinatorEndpoint coord(*cb, t);
    coord.start(text, "long.toml", h, {"dem"});
  }
  // Another scene is recorded whole once, then as a stub.
  demfdm::scene_t other{};
  other.scene_hash = 42;
  other.n_chunks = 1;
  other.text = "[run]\n";
  cb->publish(bus::channel::kScene, other);
  cb->publish(bus::channel::kScene, other);
  cb.reset();

  std::vector<fs::path> parts;
  for (const auto& de : fs::directory_iterator(dir)) parts.push_back(de.path());
  ASSERT_EQ(parts.size(), 1u);
  lcm::LogFile f(parts[0].string(), "r");
  ASSERT_TRUE(f.good());
  std::map<std::pair<std::int64_t, std::int32_t>, int> whole, stubs;
  std::set<std::int64_t> seqs;
  std::string joined;
  while (const lcm::LogEvent* e = f.readNextEvent()) {
    if (e->channel != bus::channel::kScene && e->channel != "DEMFDM_SCENE_REPEAT") continue;
    demfdm::scene_t s;
    ASSERT_GE(s.decode(e->data, 0, e->datalen), 0);
    EXPECT_TRUE(seqs.insert(s.header.seq).second) << "every publication recorded once";
    if (e->channel == bus::channel::kScene) {
      ++whole[{s.scene_hash, s.chunk_index}];
      if (s.scene_hash == static_cast<std::int64_t>(h)) joined += s.text;
    } else {
      ++stubs[{s.scene_hash, s.chunk_index}];
      EXPECT_TRUE(s.text.empty());
      EXPECT_EQ(s.origin, s.scene_hash == 42 ? "" : "long.toml");
    }
  }
  const auto sh = static_cast<std::int64_t>(h);
  EXPECT_EQ(whole, (std::map<std::pair<std::int64_t, std::int32_t>, int>{{{sh, 0}, 1}, {{sh, 1}, 1}, {{42, 0}, 1}}));
  EXPECT_EQ(joined, text);
  ASSERT_EQ(stubs.size(), 3u);
  const int repeats0 = stubs[{sh, 0}], repeats1 = stubs[{sh, 1}];
  EXPECT_GE(repeats0, 3);
  EXPECT_EQ(repeats0, repeats1);
  const int repeats42 = stubs[{42, 0}];
  EXPECT_EQ(repeats42, 1);
  EXPECT_LT(fs::file_size(parts[0]), text.size() + 20000) << "the text is in the log once";
  fs::remove_all(dir);
}

// ---- udpm on loopback (private network namespace, as root): direct receive and the kernel
// channel filter (messages/bus.hpp) ----

#include "tests/integration/process.hpp"

namespace {
std::string udpm_url(int port) {
  return bus::resolve_url("udpm://239.255.76.67:" + std::to_string(port) + "?ttl=0");
}
bool pump_until(bus::Bus& b, const std::function<bool()>& done, double timeout_s = 5.0) {
  auto t0 = std::chrono::steady_clock::now();
  while (!done()) {
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s) return false;
    b.pump(0.05);
  }
  return true;
}
// Receives short (heartbeat) and fragmented (64 KiB of scene text: LCM sends it in fragments)
// messages over udpm, and counts what the kernel dropped at the receiving socket.
void udpm_delivery(bool direct) {
  auto why = demfdm::testing::enter_private_network();
  if (!why.empty()) GTEST_SKIP() << why;
  const int port = 46000 + static_cast<int>(getpid() % 1000) + (direct ? 0 : 1000);
  if (!direct) setenv("DEMFDM_BUS_RECV", "lcm", 1);
  bus::Bus rx(udpm_url(port), 7, "rx");
  unsetenv("DEMFDM_BUS_RECV");
  bus::Bus tx(udpm_url(port), 7, "tx");
  EXPECT_EQ(rx.direct_receive(), direct);
  std::vector<std::int64_t> beats;
  std::string text;
  rx.subscribe<demfdm::heartbeat_t>(bus::channel::kHeartbeat,
                                    [&](const demfdm::heartbeat_t& h) { beats.push_back(h.progress); });
  rx.subscribe<demfdm::scene_t>(bus::channel::kScene, [&](const demfdm::scene_t& s) { text = s.text; });
  // A channel whose name extends a subscribed one is not the subscribed one.
  rx.subscribe<demfdm::nack_t>(bus::channel::kNack, [&](const demfdm::nack_t&) { ADD_FAILURE() << "NACKX read as NACK"; });
  ASSERT_TRUE(rx.kernel_filter());
  const std::int64_t drops0 = rx.kernel_drops();
  ASSERT_GE(drops0, 0);
  demfdm::scene_t s{};
  s.header.step = -1;
  s.n_chunks = 1;
  for (int i = 0; i < 65536; ++i) s.text.push_back(static_cast<char>('a' + i % 26));
  tx.publish(bus::channel::kScene, s);
  // 40 reports (nobody in rx reads them) and NACKs on a longer channel name: dropped in the
  // kernel, before any thread of rx wakes.
  for (int i = 0; i < 40; ++i) {
    auto r = report(i);
    tx.publish(bus::channel::kReport, r);
    demfdm::nack_t n{};
    n.addressee = "rx";
    tx.publish(bus::channel::kNack + "X", n);
  }
  for (int i = 0; i < 10; ++i) {
    demfdm::heartbeat_t h{};
    h.progress = i;
    h.state = "x";
    tx.publish(bus::channel::kHeartbeat, h);
  }
  if (direct) {
    // What the heartbeat thread does while the owner computes: the datagrams move to the bus's
    // queue; pump() then hands them over in order.
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    rx.drain();
  }
  ASSERT_TRUE(pump_until(rx, [&] { return beats.size() == 10 && !text.empty(); }));
  EXPECT_EQ(text, s.text);
  EXPECT_EQ(beats, (std::vector<std::int64_t>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9}));
  EXPECT_GE(rx.kernel_drops() - drops0, 80) << "reports and NACKX datagrams reached the socket";
  EXPECT_EQ(rx.stats().accepted, 11);
}
}  // namespace

TEST(Udpm, DirectReceiveDeliversShortAndFragmentedMessagesAndTheKernelDropsTheRest) { udpm_delivery(true); }
TEST(Udpm, LcmReceiveThreadWithTheKernelFilterDeliversTheSame) { udpm_delivery(false); }

TEST(Udpm, KernelFilterCanBeTurnedOff) {
  auto why = demfdm::testing::enter_private_network();
  if (!why.empty()) GTEST_SKIP() << why;
  const int port = 48000 + static_cast<int>(getpid() % 1000);
  setenv("DEMFDM_BUS_FILTER", "0", 1);
  bus::Bus rx(udpm_url(port), 7, "rx");
  unsetenv("DEMFDM_BUS_FILTER");
  bus::Bus tx(udpm_url(port), 7, "tx");
  int got = 0;
  rx.subscribe<demfdm::heartbeat_t>(bus::channel::kHeartbeat, [&](const demfdm::heartbeat_t&) { ++got; });
  EXPECT_FALSE(rx.kernel_filter());
  for (int i = 0; i < 5; ++i) {
    auto r = report(i);
    tx.publish(bus::channel::kReport, r);
  }
  demfdm::heartbeat_t h{};
  h.state = "x";
  tx.publish(bus::channel::kHeartbeat, h);
  ASSERT_TRUE(pump_until(rx, [&] { return got == 1; }));
  EXPECT_EQ(rx.stats().received, 1);  // the reports reached the process and were dropped there
}
