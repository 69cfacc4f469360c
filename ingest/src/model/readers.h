// ingest/src/model/readers.h: one reader per model format (private to ingest/; mesh.h says what they fill).
#pragma once

#include <memory>
#include <string>

#include <gdal_priv.h>

#include "heightcast/ingest/mesh.h"

namespace hc::ingest::detail {

// Multidimensional (NetCDF, HDF5) files as GDAL opens them; null when GDAL cannot.
std::shared_ptr<GDALGroup> openMultidimRoot(const std::string& path, std::shared_ptr<GDALDataset>& keep);

// Each returns "" when the file is not its format (no throw), else the format's name for messages.
std::string ugridFormat(const std::shared_ptr<GDALGroup>& root);          // ugrid_mesh.cpp
std::string sfincsRegularFormat(const std::shared_ptr<GDALGroup>& root);  // sfincs_regular.cpp
std::string hecRasFormat(const std::shared_ptr<GDALGroup>& root);         // hecras.cpp
std::string swwFormat(const std::shared_ptr<GDALGroup>& root);            // sww.cpp
std::string threeDiFormat(const std::shared_ptr<GDALGroup>& root);        // threedi.cpp
std::string tuflowFvFormat(const std::shared_ptr<GDALGroup>& root);       // tuflow_fv.cpp
bool isSelafin(const std::string& path);                                  // selafin.cpp

// The readers: throw hc::Error naming the file and what is wrong. `keep` holds the dataset the root belongs to: a
// reader's step functions keep it open.
ModelMesh readUgrid(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt);
ModelMesh readSfincsRegular(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt);
ModelMesh readHecRas(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt);
ModelMesh readSww(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt);
ModelMesh readThreeDi(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt);
ModelMesh readTuflowFv(const std::string& path, std::shared_ptr<GDALDataset> keep, const MeshReadOptions& opt);
ModelMesh readSelafin(const std::string& path, const MeshReadOptions& opt);

// TUFLOW/SMS XMDF results (xmdf.cpp): an HDF5 file GDAL opens whose root "File Type" is "Xmdf" or which holds a group
// of "Values" and "Times", with a .2dm mesh found for it: NAME.2dm for NAME.xmdf (or NAME.h5); else in the same folder
// the .2dm MODEL.2dm for MODEL_anything.xmdf (the longest such MODEL); else the folder's only .2dm. "" otherwise;
// never throws.
std::string xmdfFormat(const std::string& path);
ModelMesh readXmdf(const std::string& path, const MeshReadOptions& opt);

}  // namespace hc::ingest::detail
