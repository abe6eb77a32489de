# Error against cost for rime-bench-accuracy (gnuplot -e "dir='results'" plot.gp).
# Reads dir/results.csv; one point per setting, labelled; the reference (zero error) is left out.
if (!exists("dir")) dir = "results"
set datafile separator ","
set terminal pngcairo size 1100,750 font ",10" noenhanced
set key off
set grid
set logscale x
set xlabel "CPU time per run, s (median)"
set style textbox opaque noborder
ok(g) = (strcol(1) ne "reference" && strcol(1) ne "freezing" && strcol(24) eq "0")
set output dir."/pareto_front.png"
set title "Dam break: surge-front error against the reference vs cost"
set ylabel "mean |Z - Z_ref| / Z_ref, %"
plot dir."/results.csv" every ::1 using (ok(0) ? $12 : NaN):($19*100) with points pt 7 ps 1.3, \
     "" every ::1 using (ok(0) ? $12 : NaN):($19*100):2 with labels offset 0,0.8 font ",8"
set output dir."/pareto_density.png"
set title "Dam break: mean density error over the run vs cost"
set ylabel "mean average density error, %"
set logscale y
plot dir."/results.csv" every ::1 using (ok(0) ? $12 : NaN):($16*100) with points pt 7 ps 1.3, \
     "" every ::1 using (ok(0) ? $12 : NaN):($16*100):2 with labels offset 0,0.8 font ",8"
set output dir."/pareto_position.png"
set title "Dam break: front particles' distance from the reference run (same spacing) vs cost"
set ylabel "mean displacement, d_p"
unset logscale y
plot dir."/results.csv" every ::1 using (ok(0) ? $12 : NaN):21 with points pt 7 ps 1.3, \
     "" every ::1 using (ok(0) ? $12 : NaN):21:2 with labels offset 0,0.8 font ",8"
