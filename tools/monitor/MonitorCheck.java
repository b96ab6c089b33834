// Headless check of the monitor (make monitor-check): reads an lcm-logger file recorded from a running
// scancelld and decodes every SCANCELL_STATUS event twice, as lcm-spy would (LCMTypeDatabase finds the class
// by the fingerprint in the message's first 8 bytes, from the classpath) and through the generated type.
// Prints each decoded message; exits 1 when none decodes or a field is out of its documented range.
import java.io.ByteArrayInputStream;
import java.io.DataInputStream;
import java.io.IOException;

import lcm.logging.Log;
import lcm.spy.LCMTypeDatabase;

public class MonitorCheck {
  public static void main(String[] args) throws IOException {
    if (args.length != 1) {
      System.err.println("usage: MonitorCheck FILE.lcmlog");
      System.exit(2);
    }
    LCMTypeDatabase types = new LCMTypeDatabase();
    Log log = new Log(args[0], "r");
    int decoded = 0, bad = 0;
    long now = System.currentTimeMillis() * 1000L;
    while (true) {
      Log.Event ev;
      try {
        ev = log.readNext();
      } catch (java.io.EOFException e) {
        break;
      }
      if (!ev.channel.equals("SCANCELL_STATUS")) continue;
      long fingerprint = new DataInputStream(new ByteArrayInputStream(ev.data)).readLong();
      Class<?> cls = types.getClassByFingerprint(fingerprint);
      if (cls == null || !cls.getName().equals("scancell.status_t")) {
        System.out.printf("event %d: fingerprint %016x not found on the classpath (got %s): lcm-spy could not decode it%n",
                          ev.eventNumber, fingerprint, cls);
        ++bad;
        continue;
      }
      scancell.status_t s = new scancell.status_t(ev.data);
      boolean ok = Math.abs(s.utime - now) < 3600L * 1000000L && (s.daemon_state.equals("idle") || s.daemon_state.equals("busy"))
                   && s.job_id >= 0 && s.view >= 0 && s.views >= s.view && s.estimated_coverage >= 0 && s.estimated_coverage <= 1
                   && s.measured_coverage >= 0 && s.measured_coverage <= 1;
      System.out.printf("SCANCELL_STATUS %s: utime %d daemon_state %s job_id %d job_state '%s' view %d/%d estimated %.3f measured %.3f%s%n",
                        cls.getName(), s.utime, s.daemon_state, s.job_id, s.job_state, s.view, s.views, s.estimated_coverage,
                        s.measured_coverage, ok ? "" : "  <- out of range");
      if (ok) ++decoded;
      else ++bad;
    }
    System.out.printf("%d SCANCELL_STATUS messages decoded, %d failed%n", decoded, bad);
    System.exit(decoded > 0 && bad == 0 ? 0 : 1);
  }
}
