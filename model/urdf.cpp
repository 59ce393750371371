#include "model/urdf.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <locale>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <vector>

#include <console_bridge/console.h>
#include <tinyxml.h>
#include <urdf_parser/urdf_parser.h>

#include "core/error.h"
#include "core/io.h"
#include "core/limits.h"

namespace mcms {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// urdfdom reports why it rejects a file through console_bridge (to stderr by default):
// collect its messages while parsing, so the error names them and nothing else is printed.
class CollectingHandler : public console_bridge::OutputHandler {
 public:
  void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
    if (level >= console_bridge::CONSOLE_BRIDGE_LOG_WARN) messages.push_back(text);
  }
  std::vector<std::string> messages;
};

std::mutex& ParserMutex() {
  static std::mutex m;  // console_bridge's handler is global
  return m;
}

// urdfdom's model of `xml`, its console messages collected (one parse at a time: the
// console handler is global); InputError naming `source` with them when it fails.
urdf::ModelInterfaceSharedPtr ParseWithUrdfdom(const std::string& xml, const std::string& source) {
  urdf::ModelInterfaceSharedPtr model;
  std::lock_guard<std::mutex> lock(ParserMutex());
  CollectingHandler handler;
  console_bridge::OutputHandler* previous = console_bridge::getOutputHandler();
  console_bridge::useOutputHandler(&handler);
  try {
    model = urdf::parseURDF(xml);
  } catch (const std::exception& e) {
    handler.messages.push_back(e.what());
    model.reset();
  }
  console_bridge::useOutputHandler(previous);
  if (!model) {
    std::string why;
    for (const auto& m : handler.messages) why += (why.empty() ? "" : "; ") + m;
    Throw(source, ": not a URDF that urdfdom can read: ", why.empty() ? std::string("(no reason given)") : why);
  }
  return model;
}

Pose ToPose(const urdf::Pose& p) {
  const Eigen::Quaterniond q(p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z);
  const double n = q.norm();
  return Pose{(n > 0 ? Eigen::Quaterniond(q.coeffs() / n) : Eigen::Quaterniond::Identity()).toRotationMatrix(),
              Vec3(p.position.x, p.position.y, p.position.z)};
}

// "a, b, c" of at most `max` names, then "and N more".
std::string NameList(const std::vector<std::string>& names, size_t max = 24) {
  std::string s;
  for (size_t i = 0; i < names.size() && i < max; ++i) s += (i ? ", " : "") + names[i];
  if (names.size() > max) s += ", and " + std::to_string(names.size() - max) + " more";
  return s;
}

std::vector<std::string> LinkNames(const urdf::ModelInterface& m) {
  std::vector<std::string> v;
  for (const auto& [name, link] : m.links_) v.push_back(name);
  return v;
}

bool Movable(const urdf::Joint& j) {
  return j.type == urdf::Joint::REVOLUTE || j.type == urdf::Joint::CONTINUOUS || j.type == urdf::Joint::PRISMATIC;
}

const char* TypeText(int type) {
  switch (type) {
    case urdf::Joint::REVOLUTE: return "revolute";
    case urdf::Joint::CONTINUOUS: return "continuous";
    case urdf::Joint::PRISMATIC: return "prismatic";
    case urdf::Joint::FLOATING: return "floating";
    case urdf::Joint::PLANAR: return "planar";
    case urdf::Joint::FIXED: return "fixed";
    default: return "unknown";
  }
}

// The leaves under `base` with the number of movable joints on their path and their last
// movable joint ("" when none), walked without recursion (a chain of 60,000 fixed links
// must not overflow the stack).
struct Leaf {
  int movable = 0;
  std::string name, last_movable;
};
// Joints whose parents close on themselves never reach the root: named, since no
// --base-link opens them. Each link is walked up once (links known to reach the root end a
// walk), so a deep tree costs its size.
void RequireNoLoop(const urdf::ModelInterface& m, const std::string& source) {
  std::map<std::string, int> state;  // 1: on the current walk, 2: reaches the root
  for (const auto& [name, start] : m.links_) {
    std::vector<urdf::LinkConstSharedPtr> walk;
    urdf::LinkConstSharedPtr l = start;
    while (l && state[l->name] == 0) {
      state[l->name] = 1;
      walk.push_back(l);
      l = l->getParent();
    }
    if (l && state[l->name] == 1) {
      std::vector<std::string> joints;
      bool in_loop = false;
      for (const auto& w : walk) {
        in_loop = in_loop || w->name == l->name;
        if (in_loop && w->parent_joint) joints.push_back(w->parent_joint->name);
      }
      Throw(source, ": joints ", NameList(joints), " form a closed loop (link '", l->name,
            "' is its own ancestor); a URDF is a tree: give each link one parent, none of them below it");
    }
    for (const auto& w : walk) state[w->name] = 2;
  }
}

std::vector<Leaf> Leaves(const urdf::ModelInterface& m, const urdf::LinkConstSharedPtr& base) {
  std::vector<Leaf> out;
  std::vector<std::pair<urdf::LinkConstSharedPtr, Leaf>> stack{{base, Leaf{0, base->name, ""}}};
  while (!stack.empty()) {
    auto [link, at] = stack.back();
    stack.pop_back();
    if (link->child_joints.empty()) {
      at.name = link->name;
      out.push_back(at);
      continue;
    }
    for (const auto& cj : link->child_joints) {
      const auto child = m.getLink(cj->child_link_name);
      if (!child) continue;
      Leaf next = at;
      if (Movable(*cj)) ++next.movable, next.last_movable = cj->name;
      stack.push_back({child, next});
    }
  }
  return out;
}

// Mass and first moment (sum m p) of `link` and every link below it, in the frame T (frame
// -> link), the joints below at zero; the subtree below `stop` (the chain's next movable
// joint) is not included. Without recursion. A mass of 0 is a massless link (ROS's virtual
// frames: ee_link, tool0).
void AddSubtree(const urdf::ModelInterface& m, const urdf::LinkConstSharedPtr& top, const Pose& T0,
                const std::string& stop, const std::string& source, double* mass, Vec3* moment, bool* any) {
  std::vector<std::pair<urdf::LinkConstSharedPtr, Pose>> stack{{top, T0}};
  while (!stack.empty()) {
    const auto [link, T] = stack.back();
    stack.pop_back();
    if (link->inertial) {
      const double mk = link->inertial->mass;
      const Pose at = ToPose(link->inertial->origin);
      if (!(std::isfinite(mk) && mk >= 0))
        Throw(source, ": link '", link->name, "' has an <inertial> mass of ", mk,
              "; expected a finite mass >= 0 in kg (0 for a massless link)");
      if (!at.t.allFinite() || !at.R.allFinite())
        Throw(source, ": link '", link->name, "' has a non-finite <inertial> <origin>");
      if (mk > 0) {
        *mass += mk;
        *moment += mk * (T * at.t);
      }
      *any = true;
    }
    for (const auto& cj : link->child_joints) {
      if (cj->name == stop) continue;
      const auto child = m.getLink(cj->child_link_name);
      if (child) stack.push_back({child, T * ToPose(cj->parent_to_joint_origin_transform)});
    }
  }
}

// A tool-like link name (the frame a user measures or works at): lower is likelier.
int ToolLikeRank(std::string name) {
  std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return std::tolower(c); });
  static const char* kExact[] = {"tool0", "tool", "tcp", "tool_tip", "flange", "ee_link", "end_effector"};
  for (int k = 0; k < static_cast<int>(std::size(kExact)); ++k)
    if (name == kExact[k]) return k;
  for (const char* part : {"tcp", "tool", "tip", "ee", "effector", "flange", "prism"})
    if (name.find(part) != std::string::npos) return 20;
  return 100;
}

std::string Num(double v) {
  if (v == 0.0) v = 0.0;  // no "-0"
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}
std::string Triple(const Vec3& v) { return Num(v.x()) + " " + Num(v.y()) + " " + Num(v.z()); }

// An XML comment may not hold "--".
std::string CommentText(std::string s) {
  for (size_t p; (p = s.find("--")) != std::string::npos;) s.replace(p, 2, "- -");
  return " " + s + " ";
}

// Link frame i-1 to the joint's URDF frame of a DH joint (the DH link transform split in
// the part before the joint's motion and the tail after it): see UrdfText's comment.
struct DhSplit {
  Pose origin, tail;
};
Pose Rz(double a) { return Pose{Eigen::AngleAxisd(a, Vec3::UnitZ()).toRotationMatrix(), Vec3::Zero()}; }
Pose Rx(double a) { return Pose{Eigen::AngleAxisd(a, Vec3::UnitX()).toRotationMatrix(), Vec3::Zero()}; }
Pose Tz(double d) { return Pose{Mat3::Identity(), Vec3(0, 0, d)}; }
Pose Tx(double a) { return Pose{Mat3::Identity(), Vec3(a, 0, 0)}; }
DhSplit SplitDh(ChainConvention c, const Joint& j) {
  const bool rev = j.type == JointType::kRevolute;
  if (c == ChainConvention::kStandard) {
    // Rz(theta + q) Tz(d + q') Tx(a) Rx(alpha)
    if (rev) return {Rz(j.theta_offset), Tz(j.d) * Tx(j.a) * Rx(j.alpha)};
    return {Rz(j.theta_offset) * Tz(j.d), Tx(j.a) * Rx(j.alpha)};
  }
  // Rx(alpha) Tx(a) Rz(theta + q) Tz(d + q')
  if (rev) return {Rx(j.alpha) * Tx(j.a) * Rz(j.theta_offset), Tz(j.d)};
  return {Rx(j.alpha) * Tx(j.a) * Rz(j.theta_offset) * Tz(j.d), Pose::Identity()};
}

std::string XmlName(const std::string& s) {
  std::string o;
  for (char c : s) o += (std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-') ? c : '_';
  return o.empty() ? std::string("joint") : o;
}

std::string OriginXml(const Pose& T) {
  return "<origin xyz=\"" + Triple(T.t) + "\" rpy=\"" + Triple(RpyOf(T.R)) + "\"/>";
}

std::string InertialXml(double mass, const Vec3& com) {
  // The inertia tensor is not known from a DH table; a small positive one keeps parsers happy.
  return "    <inertial>\n      <origin xyz=\"" + Triple(com) + "\" rpy=\"0 0 0\"/>\n      <mass value=\"" + Num(mass) +
         "\"/>\n      <inertia ixx=\"1e-6\" ixy=\"0\" ixz=\"0\" iyy=\"1e-6\" iyz=\"0\" izz=\"1e-6\"/>\n    </inertial>\n";
}

// A new URDF of a DH chain.
std::string DhChainUrdf(const RobotModel& robot, const std::map<std::string, std::string>& comments) {
  const int n = robot.NumJoints();
  std::ostringstream x;
  const bool urdf = robot.Convention() == ChainConvention::kUrdf;
  x << "<?xml version=\"1.0\"?>\n<!--"
    << CommentText(urdf ? "written by mcms from the URDF-convention chain of robot '" + robot.Name() +
                              "' (its YAML form): one link per joint, the tool as the fixed link 'tool'"
                        : "written by mcms from the " +
                              std::string(robot.Convention() == ChainConvention::kStandard ? "standard" : "modified") +
                              " DH table of robot '" + robot.Name() +
                              "'; joint i's link frame sits on its axis, the DH frame follows it by the link's a, "
                              "alpha (and d)")
    << "-->\n";
  x << "<robot name=\"" << XmlName(robot.Name()) << "\">\n";
  const bool masses = robot.HasMasses();
  x << "  <link name=\"base_link\"/>\n";
  std::string parent = "base_link";
  Pose tail;
  std::set<std::string> used{"base_link", "tool"};
  for (int i = 0; i < n; ++i) {
    const Joint& j = robot.Joints()[i];
    if (j.Harmonics() > 0)
      Throw("robot '", robot.Name(), "': joint ", j.name, " has error motion, which a URDF cannot hold");
    DhSplit s;
    if (urdf) {
      // origin, then the joint's own offset (theta_offset or d) at the joint.
      Pose motion;
      if (j.type == JointType::kRevolute)
        motion.R = Eigen::AngleAxisd(j.theta_offset, j.axis).toRotationMatrix();
      else
        motion.t = j.d * j.axis;
      s = {j.origin * motion, Pose::Identity()};
    } else {
      s = SplitDh(robot.Convention(), j);
    }
    std::string name = XmlName(j.name.empty() ? "joint_" + std::to_string(i + 1) : j.name);
    while (used.count(name) || used.count(name + "_link")) name += "_";
    used.insert(name);
    const std::string link = name + "_link";
    used.insert(link);
    const Pose origin = tail * s.origin;
    tail = s.tail;
    x << "  <link name=\"" << link << "\">\n";
    if (masses && j.mass_kg > 0) x << InertialXml(*j.mass_kg, tail * j.com_m);
    x << "  </link>\n";
    const bool rev = j.type == JointType::kRevolute;
    const bool open = !std::isfinite(j.lower) || !std::isfinite(j.upper);
    x << "  <joint name=\"" << name << "\" type=\"" << (rev ? (open ? "continuous" : "revolute") : "prismatic")
      << "\">\n";
    if (const auto c = comments.find(j.name); c != comments.end())
      x << "    <!--" << CommentText(c->second) << "-->\n";
    x << "    <parent link=\"" << parent << "\"/>\n    <child link=\"" << link << "\"/>\n    " << OriginXml(origin)
      << "\n    <axis xyz=\"" << (urdf ? Triple(j.axis) : std::string("0 0 1")) << "\"/>\n";
    if (!j.mimics.empty())
      x << "    <mimic joint=\"" << XmlName(j.mimics) << "\" multiplier=\"" << Num(j.mimic_multiplier) << "\" offset=\""
        << Num(j.mimic_offset) << "\"/>\n";
    if (!rev || !open) {
      // effort and velocity are not known from a DH table (0: not given).
      const double lo = std::isfinite(j.lower) ? j.lower : -1e3, hi = std::isfinite(j.upper) ? j.upper : 1e3;
      x << "    <limit lower=\"" << Num(lo) << "\" upper=\"" << Num(hi) << "\" effort=\"0\" velocity=\"0\"/>\n";
    }
    x << "  </joint>\n";
    parent = link;
  }
  x << "  <link name=\"tool\">\n";
  const ToolMass& tm = robot.Tool();
  if (masses && tm.mass_kg > 0) x << InertialXml(tm.mass_kg, robot.T_flange_tool().Inverse() * tm.com_m);
  x << "  </link>\n";
  x << "  <joint name=\"tool_joint\" type=\"fixed\">\n    <parent link=\"" << parent
    << "\"/>\n    <child link=\"tool\"/>\n    " << OriginXml(tail * robot.T_flange_tool()) << "\n  </joint>\n";
  // The joints mimic joints follow, where the chain does not hold them: each on a massless
  // branch off the base, its range the one its first mimic joint's limits imply.
  std::set<std::string> drivers;
  for (const Joint& j : robot.Joints()) {
    if (j.mimics.empty() || drivers.count(j.mimics)) continue;
    bool in_chain = false;
    for (const Joint& k : robot.Joints()) in_chain |= k.name == j.mimics;
    if (in_chain) continue;
    drivers.insert(j.mimics);
    const std::string name = XmlName(j.mimics);
    double lo = (j.lower - j.mimic_offset) / j.mimic_multiplier, hi = (j.upper - j.mimic_offset) / j.mimic_multiplier;
    if (lo > hi) std::swap(lo, hi);
    x << "  <link name=\"" << name << "_driver\"/>\n  <joint name=\"" << name << "\" type=\""
      << (j.type == JointType::kRevolute ? "revolute" : "prismatic") << "\">\n    <parent link=\"base_link\"/>\n"
      << "    <child link=\"" << name << "_driver\"/>\n    <axis xyz=\"" << Triple(j.axis) << "\"/>\n"
      << "    <limit lower=\"" << Num(std::isfinite(lo) ? lo : -1e3) << "\" upper=\"" << Num(std::isfinite(hi) ? hi : 1e3)
      << "\" effort=\"0\" velocity=\"0\"/>\n  </joint>\n";
  }
  x << "</robot>\n";
  return x.str();
}

}  // namespace

bool IsUrdfFile(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == ".urdf") return true;
  if (ext == ".yaml" || ext == ".yml") return false;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return false;
  const std::string text = ReadTextFile(path);
  const size_t p = text.find_first_not_of(" \t\r\n\xEF\xBB\xBF");
  return p != std::string::npos && text[p] == '<' && text.find("<robot") != std::string::npos;
}

RobotModel RobotModel::Read(const std::filesystem::path& path, const ChainSelection& chain) {
  if (IsUrdfFile(path)) return ReadUrdf(path, chain);
  if (!chain.base_link.empty() || !chain.tip_link.empty())
    Throw("robot file ", path.string(), ": --base-link and --tip-link pick a chain of a URDF; this is a YAML "
          "description, whose joints are the chain");
  return Parse(ReadTextFile(path), "robot file " + path.string());
}

LinkMount MountOnChain(const RobotModel& robot, const std::string& link) {
  const UrdfSource* u = robot.Urdf();
  if (!u) Throw("a sensor on link '", link, "': robot '", robot.Name(), "' is not a URDF, which names its links");
  const urdf::ModelInterfaceSharedPtr model = ParseWithUrdfdom(u->text, u->source);
  const auto start = model->getLink(link);
  if (!start)
    Throw(u->source, ": a sensor on link '", link, "', which is not a link of the URDF (links: ",
          NameList(LinkNames(*model)), ")");
  LinkMount out;
  out.link = link;
  Pose T;  // T_<current link>_<sensor link>
  for (auto l = start; l;) {
    if (l->name == u->base_link) {
      out.frame = 0;
      out.R_frame_link = T.R;
      return out;
    }
    const auto j = l->parent_joint;
    if (!j) break;
    for (int i = 0; i < robot.NumJoints(); ++i)
      if (robot.Joints()[i].name == j->name) {
        out.frame = i + 1;
        out.R_frame_link = T.R;
        return out;
      }
    if (j->type != urdf::Joint::FIXED)
      Throw(u->source, ": a sensor on link '", link, "', which moves with joint '", j->name,
            "', not a joint of the chain from '", u->base_link, "' to '", u->tip_link,
            "': a sensor is read on the chain's links");
    T = ToPose(j->parent_to_joint_origin_transform) * T;
    l = model->getLink(j->parent_link_name);
  }
  Throw(u->source, ": a sensor on link '", link, "', which is not on the chain from '", u->base_link, "' to '",
        u->tip_link, "' (nor fixed to one of its links)");
}

namespace {

// The mesh files a URDF names (<mesh filename>, relative to its folder or file://) are part
// of what a user keeps beside it: recorded as inputs of the run, so that no output replaces
// one (issue 53: calib-robot -o meshes/base.stl). package:// and remote names are not
// resolved here.
void NoteMeshFiles(const std::string& xml, const std::filesystem::path& urdf) {
  TiXmlDocument doc;
  doc.Parse(xml.c_str());
  if (doc.Error() || !doc.RootElement()) return;
  std::vector<const TiXmlElement*> stack{doc.RootElement()};
  while (!stack.empty()) {
    const TiXmlElement* e = stack.back();
    stack.pop_back();
    if (e->ValueStr() == "mesh" && e->Attribute("filename")) {
      std::string f = e->Attribute("filename");
      if (f.rfind("file://", 0) == 0) f = f.substr(7);
      if (!f.empty() && f.find("://") == std::string::npos)
        NoteInputRead(std::filesystem::path(f).is_absolute() ? std::filesystem::path(f) : urdf.parent_path() / f);
    }
    for (const TiXmlElement* c = e->FirstChildElement(); c; c = c->NextSiblingElement()) stack.push_back(c);
  }
}

}  // namespace

RobotModel ReadUrdf(const std::filesystem::path& path, const ChainSelection& chain) {
  const std::string xml = ReadTextFile(path);
  RobotModel r = ParseUrdf(xml, "robot file " + path.string(), chain);
  NoteMeshFiles(xml, path);
  return r;
}

RobotModel ParseUrdf(const std::string& xml, const std::string& source, const ChainSelection& chain) {
  {
    // The XML parser recurses per nested element: a file nested 100,000 deep overflows the
    // stack. A URDF nests some 5 levels (robot, link, visual, geometry, mesh).
    int depth = 0;
    for (size_t i = xml.find('<'); i != std::string::npos; i = xml.find('<', i + 1)) {
      if (i + 1 >= xml.size() || xml[i + 1] == '?' || xml[i + 1] == '!') continue;
      if (xml[i + 1] == '/') {
        --depth;
        continue;
      }
      const size_t close = xml.find('>', i);
      if (close != std::string::npos && xml[close - 1] == '/') continue;
      if (++depth > 100) Throw(source, ": XML elements nested more than 100 deep; a URDF nests a few levels");
    }
  }
  if (xml.find("xmlns:xacro") != std::string::npos || xml.find("<xacro:") != std::string::npos)
    Throw(source, ": a xacro file (a URDF written with macros, ROS's xacro); expand it to a URDF first: "
                  "`xacro ",
          source.rfind("robot file ", 0) == 0 ? source.substr(11) : source,
          " > robot.urdf` (package ros-xacro, or `ros2 run xacro xacro`), then give robot.urdf");
  {
    size_t links = 0;
    for (size_t i = xml.find("<link"); i != std::string::npos; i = xml.find("<link", i + 5)) ++links;
    if (links > static_cast<size_t>(kMaxRobotLinks))
      Throw(source, ": ", links, " <link> elements; a robot has at most ", kMaxRobotLinks,
            " (the largest real robots have some hundreds)");
  }
  {
    // urdfdom reads a mass or an inertial origin it cannot parse ("nan", "inf") as 0: check
    // them as written.
    TiXmlDocument doc;
    doc.Parse(xml.c_str());
    const TiXmlElement* root = doc.Error() ? nullptr : doc.RootElement();
    for (const TiXmlElement* l = root ? root->FirstChildElement("link") : nullptr; l; l = l->NextSiblingElement("link"))
      for (const TiXmlElement* in = l->FirstChildElement("inertial"); in; in = in->NextSiblingElement("inertial")) {
        const char* name = l->Attribute("name");
        const auto Finite = [](const char* text, int count) {
          std::istringstream is(text ? text : "");
          is.imbue(std::locale::classic());
          for (int k = 0; k < count; ++k) {
            double v;
            if (!(is >> v) || !std::isfinite(v)) return false;
          }
          return true;
        };
        const TiXmlElement* m = in->FirstChildElement("mass");
        if (m && !Finite(m->Attribute("value"), 1))
          Throw(source, ": link '", name ? name : "?", "' has an <inertial> mass of '",
                m->Attribute("value") ? m->Attribute("value") : "", "'; expected a finite mass >= 0 in kg");
        const TiXmlElement* o = in->FirstChildElement("origin");
        if (o && o->Attribute("xyz") && !Finite(o->Attribute("xyz"), 3))
          Throw(source, ": link '", name ? name : "?", "' has an <inertial> <origin xyz='", o->Attribute("xyz"),
                "'>; expected three finite numbers (m)");
      }
  }
  const urdf::ModelInterfaceSharedPtr model = ParseWithUrdfdom(xml, source);
  const urdf::ModelInterface& m = *model;
  const auto root = m.getRoot();
  if (!root) Throw(source, ": the URDF has no root link");
  RequireNoLoop(m, source);
  const std::string base = chain.base_link.empty() ? root->name : chain.base_link;
  const auto base_link = m.getLink(base);
  if (!base_link)
    Throw(source, ": --base-link '", base, "' is not a link of the URDF (links: ", NameList(LinkNames(m)), ")");
  std::string tip = chain.tip_link;
  std::string tip_note;
  if (tip.empty()) {
    const std::vector<Leaf> leaves = Leaves(m, base_link);
    int best = 0;
    for (const Leaf& l : leaves) best = std::max(best, l.movable);
    if (best == 0) Throw(source, ": no movable joint below base link '", base, "'; give --base-link");
    std::vector<Leaf> cands;
    for (const Leaf& l : leaves)
      if (l.movable == best) cands.push_back(l);
    std::sort(cands.begin(), cands.end(), [](const Leaf& a, const Leaf& b) {
      return std::make_pair(ToolLikeRank(a.name), a.name) < std::make_pair(ToolLikeRank(b.name), b.name);
    });
    bool one_chain = true;
    for (const Leaf& l : cands) one_chain &= l.last_movable == cands.front().last_movable;
    if (!one_chain) {
      // Name every leaf with its depth, the deepest first.
      std::vector<Leaf> all = leaves;
      std::sort(all.begin(), all.end(), [](const Leaf& a, const Leaf& b) {
        return std::make_pair(-a.movable, a.name) < std::make_pair(-b.movable, b.name);
      });
      std::vector<std::string> named;
      for (const Leaf& l : all) named.push_back(l.name + " (" + std::to_string(l.movable) + ")");
      Throw(source, ": the tip of the chain is ambiguous: ", cands.size(), " links lie ", best,
            " movable joints below '", base, "' on different chains; give --tip-link (leaves with their movable "
            "joints below the base: ", NameList(named), ")");
    }
    // Leaves on one chain (rigid frames after its last joint: a tool frame, a sensor): the
    // chain is the same, the tool-like one is the tip.
    tip = cands.front().name;
    if (cands.size() > 1) {
      std::vector<std::string> others;
      for (size_t k = 1; k < cands.size(); ++k) others.push_back(cands[k].name);
      tip_note = "tip link '" + tip + "' taken as the tool (after joint " + cands.front().last_movable +
                 ", beside " + NameList(others) + " on the same joints); give --tip-link to name another";
    }
  }
  auto link = m.getLink(tip);
  if (!link) Throw(source, ": --tip-link '", tip, "' is not a link of the URDF (links: ", NameList(LinkNames(m)), ")");
  // The joints from the base to the tip.
  std::vector<urdf::JointConstSharedPtr> path;
  std::vector<std::string> above;
  while (link->name != base) {
    above.push_back(link->name);
    const auto pj = link->parent_joint;
    if (!pj) {
      Throw(source, ": no chain from base link '", base, "' to tip link '", tip, "': '", base,
            "' is not above it (the links from the tip up to the root: ", NameList(above), ")");
    }
    path.push_back(pj);
    link = m.getLink(pj->parent_link_name);
    if (!link) Throw(source, ": joint '", pj->name, "' names a parent link '", pj->parent_link_name, "' that is missing");
  }
  std::reverse(path.begin(), path.end());

  std::vector<Joint> joints;
  std::vector<Pose> prefixes;
  std::vector<std::string> child_links;
  Pose prefix;
  for (const auto& j : path) {
    if (j->type == urdf::Joint::FIXED) {
      prefix = prefix * ToPose(j->parent_to_joint_origin_transform);
      continue;
    }
    if (!Movable(*j))
      Throw(source, ": joint '", j->name, "' in the chain from '", base, "' to '", tip, "' is ", TypeText(j->type),
            "; a serial chain takes revolute, continuous, prismatic and fixed joints");
    Joint jt;
    if (j->mimic) {
      // Follows its driving joint (the one a log records): q = multiplier q_driver + offset.
      jt.mimics = j->mimic->joint_name;
      jt.mimic_multiplier = j->mimic->multiplier;
      jt.mimic_offset = j->mimic->offset;
      const auto driver = m.getJoint(jt.mimics);
      if (!driver)
        Throw(source, ": joint '", j->name, "' mimics joint '", jt.mimics, "', which is not in the URDF");
      if (!Movable(*driver))
        Throw(source, ": joint '", j->name, "' mimics joint '", jt.mimics, "', which is ", TypeText(driver->type),
              "; a mimic joint follows a revolute, continuous or prismatic joint");
    }
    jt.name = j->name;
    jt.type = j->type == urdf::Joint::PRISMATIC ? JointType::kPrismatic : JointType::kRevolute;
    const Vec3 axis(j->axis.x, j->axis.y, j->axis.z);
    if (!(axis.norm() > 1e-9) || !axis.allFinite())
      Throw(source, ": joint '", j->name, "' has a zero or non-finite <axis>; a movable joint needs a direction");
    jt.axis = axis.normalized();
    jt.origin = prefix * ToPose(j->parent_to_joint_origin_transform);
    if (j->type != urdf::Joint::CONTINUOUS) {
      if (!j->limits)
        Throw(source, ": ", TypeText(j->type), " joint '", j->name, "' has no <limit>; give lower and upper");
      jt.lower = j->limits->lower;
      jt.upper = j->limits->upper;
      if (!(jt.lower < jt.upper))
        Throw(source, ": joint '", j->name, "' has limits lower ", jt.lower, " >= upper ", jt.upper,
              "; give lower < upper");
    } else {
      jt.lower = -kInf;
      jt.upper = kInf;
    }
    prefixes.push_back(prefix);
    child_links.push_back(j->child_link_name);
    joints.push_back(jt);
    prefix = Pose::Identity();
    if (static_cast<int>(joints.size()) > kMaxRobotJoints)
      Throw(source, ": more than ", kMaxRobotJoints, " movable joints from '", base, "' to '", tip,
            "'; a robot's chain has at most ", kMaxRobotJoints);
  }
  if (joints.empty())
    Throw(source, ": the chain from '", base, "' to '", tip, "' has no movable joint (only fixed ones)");
  const Pose T_flange_tool = prefix;

  // The links' masses: each joint's link carries everything rigidly attached to it.
  bool any = false;
  std::vector<double> mass(joints.size(), 0.0);
  std::vector<Vec3> moment(joints.size(), Vec3::Zero());
  for (size_t i = 0; i < joints.size(); ++i) {
    const std::string stop = i + 1 < joints.size() ? joints[i + 1].name : std::string();
    AddSubtree(m, m.getLink(child_links[i]), Pose::Identity(), stop, source, &mass[i], &moment[i], &any);
  }
  if (any)
    for (size_t i = 0; i < joints.size(); ++i) {
      joints[i].mass_kg = mass[i];
      joints[i].com_m = mass[i] > 0 ? Vec3(moment[i] / mass[i]) : Vec3::Zero();
    }

  auto src = std::make_shared<UrdfSource>();
  src->text = xml;
  src->source = source;
  src->base_link = base;
  src->tip_link = tip;
  src->prefix = prefixes;
  src->tip_note = tip_note;
  for (const auto& [name, j] : m.joints_) src->all_joints.push_back(name);
  RobotModel robot(m.getName().empty() ? tip : m.getName(), ChainConvention::kUrdf, joints, T_flange_tool);
  robot.SetUrdf(src);
  return robot;
}

std::string UrdfText(const RobotModel& robot, const std::map<std::string, std::string>& comments) {
  for (const Joint& j : robot.Joints())
    if (j.Harmonics() > 0)
      Throw("robot '", robot.Name(), "': joint ", j.name, " has error motion, which a URDF cannot hold");
  const UrdfSource* src = robot.Urdf();
  // A DH table, or a URDF chain read from its YAML form: a new URDF of the chain.
  if (robot.Convention() != ChainConvention::kUrdf || !src) return DhChainUrdf(robot, comments);
  TiXmlDocument doc;
  doc.Parse(src->text.c_str());
  if (doc.Error()) Throw(src->source, ": cannot be parsed again to write it back: ", doc.ErrorDesc());
  TiXmlElement* root = doc.RootElement();
  if (!root) Throw(src->source, ": no <robot> element");
  std::map<std::string, int> index;
  for (int i = 0; i < robot.NumJoints(); ++i) index[robot.Joints()[i].name] = i;
  int written = 0;
  for (TiXmlElement* je = root->FirstChildElement("joint"); je; je = je->NextSiblingElement("joint")) {
    const char* name = je->Attribute("name");
    if (!name) continue;
    const auto it = index.find(name);
    if (it == index.end()) continue;
    const int i = it->second;
    const Joint& j = robot.Joints()[i];
    // The joint's own <origin>: the model's placement without the fixed joints folded in
    // before it; the model's offset (theta_offset or d for a prismatic joint) folded in too.
    Pose motion;
    if (j.type == JointType::kRevolute)
      motion.R = Eigen::AngleAxisd(j.theta_offset, j.axis).toRotationMatrix();
    else
      motion.t = j.d * j.axis;
    const Pose own = src->prefix[i].Inverse() * j.origin * motion;
    TiXmlElement* o = je->FirstChildElement("origin");
    if (!o) {
      TiXmlElement fresh("origin");
      o = je->InsertEndChild(fresh)->ToElement();
    }
    o->SetAttribute("xyz", Triple(own.t));
    o->SetAttribute("rpy", Triple(RpyOf(own.R)));
    if (const auto c = comments.find(j.name); c != comments.end()) {
      TiXmlComment comment(CommentText(c->second).c_str());
      je->InsertBeforeChild(o, comment);
    }
    ++written;
  }
  if (written != robot.NumJoints())
    Throw(src->source, ": ", robot.NumJoints() - written, " of the chain's joints were not found to write back");
  TiXmlPrinter printer;
  printer.SetIndent("  ");
  doc.Accept(&printer);
  return printer.Str();
}

void WriteUrdf(const std::filesystem::path& path, const RobotModel& robot,
               const std::map<std::string, std::string>& comments) {
  const std::string text = UrdfText(robot, comments);
  WriteFileAtomically(path, [&](std::ostream& o) { o << text; });
}

}  // namespace mcms
