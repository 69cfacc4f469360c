// ingest/src/model/md_util.h: reading variables of multidimensional files (NetCDF, HDF5) through GDAL's multidim API,
// for the model readers (private to ingest/).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <gdal_priv.h>

#include "heightcast/ingest/mesh.h"

namespace hc::ingest::detail {

using ArrayPtr = std::shared_ptr<GDALMDArray>;

// The file's variables, read with the file's name in every message.
struct MdFile {
    std::string path;
    std::shared_ptr<GDALDataset> keep;  // the dataset the root belongs to
    std::shared_ptr<GDALGroup> root;

    [[noreturn]] void fail(const std::string& what) const;
    // The variable at `name` (a full path "/a/b/c" for HDF5 groups), or nullptr.
    ArrayPtr find(const std::string& name) const;
    // The same, or throws naming `role` ("the bed level").
    ArrayPtr open(const std::string& name, const std::string& role) const;
    // The names of the root's variables (zero-dimensional ones too).
    std::vector<std::string> names() const;
    // All of `a` as doubles, in its dimension order (exact for integer indexes).
    std::vector<double> read(const ArrayPtr& a) const;
    // Index `first` of `a`'s first dimension: the rest of `a` (a step of a (time, ...) variable).
    std::vector<double> readSlice(const ArrayPtr& a, size_t first) const;
};

// Whether the group holds every one of `all` and, when `any` is not empty, one of `any` (a format's probe; never
// throws).
bool holds(const std::shared_ptr<GDALGroup>& root, std::initializer_list<const char*> all,
           std::initializer_list<const char*> any = {});

// A text attribute ("" when missing) and a numeric one (nullopt when missing).
std::string textAttr(const ArrayPtr& a, const std::string& name);
std::optional<double> numAttr(const ArrayPtr& a, const std::string& name);
// A global attribute of the file (on its root group): text ("" when missing) or a number (nullopt when missing).
// A text attribute of the root group, without surrounding white space ("" when missing).
std::string rootText(const MdFile& f, const std::string& name);
// `s` without leading and trailing white space (models pad their names).
std::string trim(const std::string& s);
std::optional<double> rootNum(const MdFile& f, const std::string& name);
// The variable's fill value (_FillValue, missing_value), or nullopt.
std::optional<double> fillOf(const ArrayPtr& a);
// Turns the fill value, and anything at or beyond +-1e30 and NaN, into NaN in `v`; returns how many.
size_t fillToNaN(std::vector<double>& v, std::optional<double> fill);
// The sizes of `a`'s dimensions.
std::vector<size_t> shapeOf(const ArrayPtr& a);
// The nodes' coordinates from the variables xName and yName (one value a node) into m.nodeX, m.nodeY and
// m.coordsFloat32; throws when they differ in length. Returns the x variable (its dimension names the nodes).
ArrayPtr readNodes(const MdFile& f, const std::string& xName, const std::string& yName, ModelMesh& m);
// Times of a CF time variable in seconds (units "hours since ..."); throws naming the variable when its units are
// not CF's time units; checks they increase (naming the step that goes back).
std::vector<double> cfTimesS(const MdFile& f, const ArrayPtr& time);
// Checks times [s] increase strictly: throws naming `what` and the first step that does not.
void checkIncreasing(const MdFile& f, const std::vector<double>& timesS, const std::string& what);

}  // namespace hc::ingest::detail
