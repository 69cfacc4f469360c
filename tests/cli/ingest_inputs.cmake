# hc-ingest on inputs that used to give silently wrong grids (issue 11, "Ingest: silently wrong grids").
# Included at the end of tests/cli/CMakeLists.txt; every fixture is made at run time from the real rasters.

# Issue 11, "Longitudes in 0..360": hef_srtm's pixels placed at 234..238 E (a UTM 10N region) were refused with
# "no UTM zone holds it". Now ingested in UTM 10N, cell for cell the same grid as the same raster at -126..-122.
set(LON360 [[gdal_translate -q -a_srs EPSG:4326 -a_ullr 234 46 238 44 "$HC_DATA_DIR/hef_srtm.tif" e360.tif && gdal_translate -q -a_srs EPSG:4326 -a_ullr -126 46 -122 44 "$HC_DATA_DIR/hef_srtm.tif" e180.tif]])
hc_cli_test(ingest_inputs.longitudes_0_360 0 [[grid CRS +WGS 84 / UTM zone 10N]]
  --setup ${LON360} --match [[longitudes 234\.\.238 read as -126\.\.-122]] --no-match [[error]]
  --check [["$HC_INGEST" --quiet e180.tif -o e180.hcg && "$HC_INFO" e360.hcg --cells-csv a.csv > /dev/null && "$HC_INFO" e180.hcg --cells-csv b.csv > /dev/null && cmp a.csv b.csv]]
  -- ${INGEST} e360.tif -o e360.hcg)

# Issue 11, "Longitudes in 0..360", for water too: a water-surface raster at 234..238 E (a level of 2600 m over
# hef's pixels there) floods the same cells as the same raster at -126..-122 (GDAL's warp onto the terrain takes
# longitudes on the circle); compared cell for cell through hc-info's CSV, water_depth column included.
set(WATER360 [[gdal_translate -q -ot Float32 -scale 0 5000 2600 2600 e360.tif w360.tif && gdal_translate -q -ot Float32 -scale 0 5000 2600 2600 e180.tif w180.tif]])
hc_cli_test(ingest_inputs.water_longitudes_0_360 0 [[water +[1-9][0-9]* wet cells]]
  --setup "${LON360} && ${WATER360}" --no-match [[error|warning]]
  --check [["$HC_INGEST" --quiet e360.tif --water-surface w180.tif -o b.hcg && "$HC_INFO" a.hcg --cells-csv a.csv > /dev/null && "$HC_INFO" b.hcg --cells-csv b.csv > /dev/null && head -1 a.csv | grep -q water_depth && cmp a.csv b.csv]]
  -- ${INGEST} e360.tif --water-surface w360.tif -o a.hcg)

# Issue 11, "a grid that crosses the antimeridian is handled": 178..182 E goes whole into UTM zone 1N (whose
# meridian is 177 W), with no source pixel lost beyond the few a resampled edge may drop (here at most 9).
hc_cli_test(ingest_inputs.across_antimeridian 0 [[grid CRS +WGS 84 / UTM zone 1N.*lost +[0-9] valid source pixels]]
  --setup [[gdal_translate -q -a_srs EPSG:4326 -a_ullr 178 46 182 44 "$HC_DATA_DIR/hef_srtm.tif" across.tif]]
  --no-match [[error]]
  -- ${INGEST} across.tif -o across.hcg)

# The same 178..182 E raster with --t_srs: into PDC Mercator (EPSG:3832, centred on 150 W) the halves split at 180
# meet again and no pixel is lost; into EPSG:3857, whose own edge is at 180, they would lie a world apart at the
# map's two edges: refused, with the hint.
hc_cli_test(ingest_inputs.across_antimeridian_t_srs nonzero [[error: across\.tif: crosses 180 degrees of longitude, which is an edge of EPSG:3857.*EPSG:3832]]
  --setup [[gdal_translate -q -a_srs EPSG:4326 -a_ullr 178 46 182 44 "$HC_DATA_DIR/hef_srtm.tif" across.tif]]
  --absent out.hcg
  --check [["$HC_INGEST" across.tif -o ok.hcg --t_srs EPSG:3832 > ok.txt 2>&1 && grep -E 'split at 180 degrees' ok.txt && grep -E 'lost +0 valid' ok.txt]]
  -- ${INGEST} across.tif -o out.hcg --t_srs EPSG:3857)

# A global 1-degree grid without CRS, its longitudes running 20..380 (etopo1_1deg's columns rolled by 200, as a
# COARDS NetCDF has them), written as ESRI ASCII without .prj.
set(GLOBAL_NO_CRS [[gdal_translate -q -srcwin 200 0 160 181 -a_ullr 19.5 90.5 179.5 -90.5 "$HC_DATA_DIR/etopo1_1deg.tif" pa.tif && gdal_translate -q -srcwin 0 0 200 181 -a_ullr 179.5 90.5 379.5 -90.5 "$HC_DATA_DIR/etopo1_1deg.tif" pb.tif && gdalbuildvrt -q g.vrt pa.tif pb.tif && gdal_translate -q -of AAIGrid g.vrt global.asc && rm -f global.prj pa.tif pb.tif g.vrt global.asc.aux.xml]])

# Issue 11, "Global degree grids without a CRS" were built as a 360 x 180 m terrain of 1 m cells with only the
# generic "no CRS" warning. Now taken as WGS 84 (said in a warning naming --s_srs) and refused with the --t_srs hint.
hc_cli_test(ingest_inputs.global_degrees_without_crs nonzero [[warning: no CRS, and the coordinates look like degrees.*--s_srs local.*error: global\.asc: .*no UTM zone holds it.*--t_srs]]
  --setup ${GLOBAL_NO_CRS} --absent out.hcg
  -- ${INGEST} global.asc -o out.hcg)

# Issue 11, "--t_srs on global grids drops about half of the data": every longitude past 180 was lost while the
# summary said "every valid pixel checked". The same 20..380 grid into World Equidistant Cylindrical now keeps
# every valid pixel (the summary counts lost ones: 0), and its cells span the whole width of the world (x beyond
# +-19,000 km at both ends).
hc_cli_test(ingest_inputs.global_t_srs_keeps_every_pixel 0 [[split at 180 degrees.*lost +0 valid source pixels]]
  --setup ${GLOBAL_NO_CRS} --no-match [[every valid pixel checked]]
  --check [["$HC_INFO" out.hcg --cells-csv c.csv > /dev/null && awk -F, 'NR > 1 { if ($1 < lo) lo = $1
                                                                            if ($1 > hi) hi = $1 } END { print "x " lo " .. " hi
                                                                            exit !(lo < -1.9e7 && hi > 1.9e7) }' c.csv]]
  -- ${INGEST} global.asc -o out.hcg --t_srs EPSG:4087)

# The same for a global grid with its CRS, -180.5..180.5 (etopo1_1deg as bundled, a closing column repeating the
# first) into Mollweide: the pole rows crowd into few pixels, so a few percent may reach no cell, but they are
# counted and warned about, never reported as success; before, half the grid was lost.
hc_cli_test(ingest_inputs.global_mollweide_counts_lost_pixels 0 [[lost +[0-9]+ valid source pixels reached no cell \(([0-2]\.|[0-9]e)]]
  --no-match [[every valid pixel checked]]
  -- ${INGEST} ${D}/etopo1_1deg.tif -o out.hcg --t_srs ESRI:54009)

# Issue 11, "A -9999 sentinel without a NODATA line" (ESRI ASCII) became an 11.7 km cliff without a word. The gully
# DEM with its nodata 0s written as -9999 and its NODATA_value line dropped: a warning with the count (2739 pixels)
# and the fix; with --nodata -9999 no warning, and exactly the original's cells.
set(GULLY [[awk 'NR <= 5 { print
                 next }
            NR == 6 { next }
            { i = 1
              while (i <= NF) { if ($i == 0) $i = -9999
                                i++ }
              print }' "$HC_DATA_DIR/west_bijou_gully_3m.asc" > gully.asc]])
hc_cli_test(ingest_inputs.sentinel_without_nodata_line 0 [[warning: 2739 pixels \(71\.6 % of the valid ones\) hold -9999, a classic nodata sentinel.*add --nodata -9999]]
  --setup ${GULLY}
  --check [["$HC_INGEST" gully.asc -o fixed.hcg --nodata -9999 > fixed.txt 2>&1 && ! grep -F sentinel fixed.txt
"$HC_INGEST" --quiet "$HC_DATA_DIR/west_bijou_gully_3m.asc" -o orig.hcg 2> /dev/null
"$HC_INFO" fixed.hcg --cells-csv a.csv > /dev/null && "$HC_INFO" orig.hcg --cells-csv b.csv > /dev/null && cmp a.csv b.csv]]
  -- ${INGEST} gully.asc -o out.hcg)

# Issue 11, "An RGB Terrain-RGB PNG without --terrain-rgb" became a flat terrain of 0..255 m. Refused, naming
# --terrain-rgb and --band; with --band 1 the user's choice is read as asked.
hc_cli_test(ingest_inputs.rgb_image_needs_terrain_rgb_or_band nonzero [[error: [^ ]*fuji_terrainrgb\.png: has 4 8-bit bands, an RGBA image.*--terrain-rgb.*--band N]]
  --absent out.hcg
  --check [["$HC_INGEST" --quiet "$HC_DATA_DIR/fuji_terrainrgb.png" -o b1.hcg --band 1 2> /dev/null && test -s b1.hcg]]
  -- ${INGEST} ${D}/fuji_terrainrgb.png -o out.hcg)

# Issue 11, "Multi-variable NetCDF": "has no raster band" named neither the variables nor how to pick one, and
# GDAL's NETCDF:"file":var was refused with "no such file". A two-variable NetCDF (hef_srtm twice, made with
# gdalmdimtranslate): the error lists both names; each name is accepted; a wrong name lists the right ones.
set(TWO_VARS [[gdal_translate -q -of netCDF "$HC_DATA_DIR/hef_srtm.tif" a.nc && printf '%s\n' '<VRTDataset><Group name="/">' '<Dimension name="lat" size="284"/><Dimension name="lon" size="384"/>' '<Array name="elevation"><DataType>Int16</DataType><DimensionRef ref="lat"/><DimensionRef ref="lon"/><Source><SourceFilename>a.nc</SourceFilename><SourceArray>/Band1</SourceArray></Source></Array>' '<Array name="bedrock"><DataType>Int16</DataType><DimensionRef ref="lat"/><DimensionRef ref="lon"/><Source><SourceFilename>a.nc</SourceFilename><SourceArray>/Band1</SourceArray></Source></Array>' '</Group></VRTDataset>' > two.vrt && gdalmdimtranslate -q two.vrt two.nc && rm a.nc two.vrt]])
hc_cli_test(ingest_inputs.netcdf_variables_listed nonzero [[error: two\.nc: has no raster band of its own but 2 variables.*'NETCDF:"two\.nc":bedrock'.*'NETCDF:"two\.nc":elevation']]
  --setup ${TWO_VARS} --absent out.hcg
  --check [["$HC_INGEST" --quiet 'NETCDF:"two.nc":elevation' -o e.hcg 2> /dev/null && test -s e.hcg]]
  --check [[! "$HC_INGEST" 'NETCDF:"two.nc":nosuch' -o n.hcg > n.txt 2>&1
grep -F "two.nc holds no such subdataset" n.txt && grep -F "are: 'NETCDF:\"two.nc\":bedrock'" n.txt && test ! -e n.hcg]]
  -- ${INGEST} two.nc -o out.hcg)

# Issue 11, "Unnamed local CRS (broken GeoKeys)": "neither projected nor geographic (geocentric or vertical?)" guessed
# wrong and gave no way out. Now it says local (engineering) CRS and names --s_srs; --s_srs local is accepted.
hc_cli_test(ingest_inputs.local_crs_hints_s_srs nonzero [[error: loc\.tif: CRS 'unnamed' is a local \(engineering\) CRS.*--s_srs EPSG.*--s_srs local]]
  --setup [=[gdal_translate -q -a_srs 'LOCAL_CS["unnamed",UNIT["metre",1]]' "$HC_DATA_DIR/kootenai_1m.asc" loc.tif]=]
  --absent out.hcg --no-match [[geocentric or vertical]]
  --check [["$HC_INGEST" --quiet loc.tif -o ok.hcg --s_srs local 2> /dev/null && test -s ok.hcg]]
  -- ${INGEST} loc.tif -o out.hcg)

# Issue 11, smaller items: the US-survey-foot warning named the unit "Meter", and the elevations of a feet CRS were
# not mentioned. kootenai_1m declared in EPSG:2227 (California zone 3, ftUS).
hc_cli_test(ingest_inputs.us_survey_foot_named 0 [[horizontal units are US survey foot: converted to metres.*elevations taken as metres .*add --z-scale 0\.3048006096]]
  --setup [[gdal_translate -q -a_srs EPSG:2227 "$HC_DATA_DIR/kootenai_1m.asc" ft.tif]]
  --no-match [[units are Meter]]
  -- ${INGEST} ft.tif -o ft.hcg)

# Issue 11, "--min-cell coarser than the source": the only figure was against the resampled raster (0.25 m) while
# the survey differed by 1.43 m. Both are printed, named; the survey figure is the 1.43 m.
hc_cli_test(ingest_inputs.min_cell_reports_source_deviation 0 [[deviation +max [0-9.e-]+ m, RMS [0-9.e-]+ m against the [0-9]+ valid pixels of the resampled working raster.*vs source +max 1\.43[0-9]* m, RMS [0-9.e-]+ m against the 160000 valid source pixels.*lost +0 valid]]
  --no-match [[every valid pixel checked]]
  -- ${INGEST} ${D}/lidar1m_minnesota_utm15.tif -o out.hcg --min-cell 4)

# Issue 11, smaller: "every pixel is nodata" when --min-cell exceeds the raster (a 50 x 37 m raster, 100 m cells:
# the one working pixel's centre lies outside the data). Now the error says what happened and names --min-cell.
hc_cli_test(ingest_inputs.min_cell_beyond_raster nonzero [[error: [^ ]*kootenai_1m\.asc: none of the 1 x 1 working pixels of 100 m has its centre on valid data.*1850 valid pixels.*--min-cell]]
  --absent out.hcg --no-match [[every pixel is nodata]]
  -- ${INGEST} ${D}/kootenai_1m.asc -o out.hcg --min-cell 100)

# Issue 11, smaller: "--quiet still prints the whole summary". With --quiet only warnings (and errors) come out.
hc_cli_test(ingest_inputs.quiet_prints_only_warnings 0 [[^hc-ingest: warning: no CRS: coordinates taken as metres]]
  --no-match [[deviation|cells|reading|building|->]] --exists out.hcg
  --check [[test "$(wc -l < "$OUTPUT")" = 1]]
  -- ${INGEST} ${D}/kootenai_1m.asc -o out.hcg --quiet)

# The help says what --water-level connects through (issue 11, smaller: the 4-neighbour flood was undocumented).
hc_cli_test(ingest_inputs.help_names_4_connected_flood 0 [[4-connected: pixels touching only at a corner do not connect]]
  -- ${INGEST} --help)

# Issue 11, smaller: "vertical units of a feet CRS are not mentioned". With a compound CRS whose vertical part is
# in US survey feet (EPSG:2227+6360, NAVD88 height (ftUS)) the elevations are converted, and said so; the hint
# for CRSs that name no vertical unit does not appear then.
hc_cli_test(ingest_inputs.compound_crs_feet_elevations 0 [[warning: elevations are in 'US survey foot': converted to metres \(x0\.3048006096\)]]
  --setup [[gdal_translate -q -a_srs "EPSG:2227+6360" "$HC_DATA_DIR/kootenai_1m.asc" cft.tif]]
  --no-match [[often in the same unit|error]]
  -- ${INGEST} cft.tif -o out.hcg --quiet)
