# Error against cost for rime-bench-accuracy (gnuplot -e "dir='results'" plot.gp).
# Reads dir/results.csv; one point per setting; the three quality presets in red and labelled,
# the single-knob and candidate settings in grey with small labels; the reference (zero error)
# and diverged runs are left out. Log scales: the settings span two decades of cost and error.
if (!exists("dir")) dir = "results"
set datafile separator ","
set terminal pngcairo size 1200,800 font ",10" noenhanced
set key top right
set grid
set logscale xy
set xlabel "CPU time per run, s (median)"
ok(g) = (strcol(1) ne "reference" && strcol(1) ne "freezing" && strcol(24) eq "0")
preset(g) = (strcol(1) eq "preset")
knob(g) = ok(0) && !preset(0)
do for [plot_id = 1:3] {
  if (plot_id == 1) { set output dir."/pareto_front.png"; set title "Dam break: surge-front error against the reference run vs cost"; set ylabel "mean |Z - Z_ref| / Z_ref, %"; col = 19; scale = 100 }
  if (plot_id == 2) { set output dir."/pareto_density.png"; set title "Dam break: measured average density error over the run vs cost"; set ylabel "mean measured density error, %"; col = 28; scale = 100 }
  if (plot_id == 3) { set output dir."/pareto_position.png"; set title "Dam break: front particles' distance from the reference run (same spacing) vs cost"; set ylabel "mean displacement, d_p"; col = 21; scale = 1 }
  plot dir."/results.csv" every ::1 using (knob(0) ? $12 : NaN):(column(col)*scale) with points pt 7 ps 1.0 lc rgb "#888888" title "one knob / candidate", \
       "" every ::1 using (knob(0) ? $12 : NaN):(column(col)*scale):2 with labels offset 0,0.7 font ",7" tc rgb "#555555" notitle, \
       "" every ::1 using (preset(0) ? $12 : NaN):(column(col)*scale) with points pt 7 ps 2.0 lc rgb "#cc2222" title "quality presets", \
       "" every ::1 using (preset(0) ? $12 : NaN):(column(col)*scale):2 with labels offset 0,-1.1 font ",10" tc rgb "#cc2222" notitle
}
