# tests/cli/water_level.cmake: the water level field (docs/design.md section 6) end to end. Issue 11, "The water
# surface is not level": a bathtub flood at 20 m probed at up to 27 m, because dry neighbours brought terrain but
# no depth into the average. Now hc-probe and hc-export give the wet cells' level wherever water is drawn.
#
# The fixture: the 1 m LiDAR tile (379.7 - 410.8 m) flooded at 397 m, and a 60 x 60 lattice of points over it.
set(WATER_LIDAR [[$HC_INGEST --quiet "$HC_DATA_DIR/lidar1m_minnesota_utm15.tif" -o f.hcg --water-level 397 >/dev/null 2>&1 &&
awk 'BEGIN { print "x,y"
             n = 0
             while (n < 3600) { printf "%.3f,%.3f\n", 429252.313 + (int(n / 60) + 0.5) * 400 / 60, 5150485.425 + (n % 60 + 0.5) * 400 / 60
                                n++ } }' > p.csv]])

# Every point with water lies within 1 cm of 397 m (the issue's figure; the wet cells' stored levels differ from
# 397 m by float rounding, about 3e-5 m); the lattice sees both water and dry land.
hc_cli_test(probe.water_surface_is_level 0 [[cells around the points]]
  --setup ${WATER_LIDAR} --exists s.csv
  --check [[awk -F, 'NR > 1 { if ($3 == "") { dry++ } else { wet++
                                              d = $3 - 397
                                              if (d < 0) d = -d
                                              if (d > 0.01) { print "line " NR ": water surface " $3
                                                              bad = 1 } } }
                END { print wet " points with water, " dry " without"
                      exit bad || wet < 500 || dry < 500 }' s.csv]]
  -- ${PROBE} f.hcg --layer water_surface --points p.csv -o s.csv)
# The depth is level - terrain where there is water and 0 on dry land (1e-6 m: three doubles printed with 17
# digits), at the same points.
hc_cli_test(probe.water_depth_is_level_minus_terrain 0 [[cells around the points]]
  --setup ${WATER_LIDAR}
  --setup [[$HC_PROBE f.hcg --layer water_surface --points p.csv -o s.csv 2>/dev/null && $HC_PROBE f.hcg --points p.csv -o z.csv 2>/dev/null]]
  --check [[paste -d, s.csv z.csv d.csv | awk -F, 'NR > 1 { s = $3
                                                           z = $6
                                                           d = $9
                                                           if (s == "") { if (d != 0) { print "line " NR ": depth " d " on dry land"
                                                                                        bad = 1 }
                                                                          next }
                                                           e = d - (s - z)
                                                           if (e < 0) e = -e
                                                           if (e > 1e-6 || d <= 0) { print "line " NR ": depth " d ", surface " s ", terrain " z
                                                                                     bad = 1 }
                                                           wet++ }
                                               END { print wet " points with water"
                                                     exit bad || wet < 500 }']]
  -- ${PROBE} f.hcg --layer water_depth --points p.csv -o d.csv)
# hc-export writes the same field: the water surface GeoTIFF is flat at 397 m (1 cm; float32 storage).
hc_cli_test(export.water_surface_is_level 0 [[-> s\.tif]]
  --setup [[$HC_INGEST --quiet "$HC_DATA_DIR/lidar1m_minnesota_utm15.tif" -o f.hcg --water-level 397 >/dev/null 2>&1]]
  --exists s.tif
  --check [[gdalinfo -stats s.tif > info.txt 2>&1
            awk -F= '/STATISTICS_MINIMUM/ { lo = $2 } /STATISTICS_MAXIMUM/ { hi = $2 }
                     END { print "water surface " lo " .. " hi
                           exit !(lo != "" && lo > 396.99 && hi < 397.01) }' info.txt]]
  -- ${EXPORT} f.hcg --layer water_surface --resolution 2 -o s.tif)
# A grid without water has neither water layer, and says how to add one.
hc_cli_test(probe.water_depth_without_water nonzero [[^hc-probe: error: no layer 'water_depth': the grid has no water .it has: elevation. hc-ingest --water, --water-surface or --water-level adds it.]]
  --setup [[$HC_INGEST --quiet "$HC_DATA_DIR/kootenai_1m.asc" -o k.hcg >/dev/null 2>&1]]
  -- ${PROBE} k.hcg --xy 1,1 --layer water_depth)
