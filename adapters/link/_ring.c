/* The steady ring, compiled: request/reply exchanges on a byte stream, the GIL released.
 *
 * adapters/link/ring.py is the interface and the fallback (the same exchanges in Python);
 * both are run by the same tests. docs/decisions/0103-steady-ring.md says what a ring is
 * and when a driver runs one. This file only runs it:
 *
 *   run(fd, wake, deadline, expected, requests, tsyn, reply_wait, t_char,
 *       idle_since, busy_until, horizon, priority, gc_due, gc_period)
 *     -> (stop, times, rest, rest_at, idle_since, partial, bytes_in, bytes_out, realtime)
 *
 * With priority > 0 the ring runs under SCHED_FIFO at that priority (the thread's own
 * scheduling put back after it); realtime: 1 it did, 0 not asked, -errno refused.
 *
 * Exchange 0's request is on the line (its reply awaited until ``deadline``). For each
 * exchange i: the reply is read until it is whole; taken when it equals expected[i]; then
 * the line is idle TSYN (counted from the later of the reply and the
 * request's own end, at least until busy_until) and requests[i] (the next exchange's
 * request) is written; its reply awaited reply_wait after its own line time (its length
 * times t_char); an exchange whose expected reply is empty is a broadcast (no reply, the
 * line busy TSYN after its end), written only when it is due once the line is free for it
 * (gc_due, then gc_period after each one written); one not due is left out, its two times
 * NaN, and the next request follows in its place. The ring stops at anything else, before
 * acting on it, with a reason: see STOP_* below and RingStop in ring.py.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <errno.h>
#include <math.h>
#include <poll.h>
#include <sched.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

enum {
    STOP_END = 0,     /* every planned exchange done: the last reply taken */
    STOP_DIFFER = 1,  /* a reply other than expected (rest: its bytes) */
    STOP_TIMEOUT = 2, /* no whole reply by the deadline (rest: what came) */
    STOP_WAKE = 3,    /* the wake descriptor is readable: something else wants the loop */
    STOP_HORIZON = 4, /* the next request would go after the horizon */
    STOP_BYTES = 5,   /* bytes in an idle time (left unread) */
    STOP_PORT = 6,    /* the port reports an error or a hang-up (left to the loop's reader) */
    STOP_WRITE = 7,   /* a request went out short or not at all (partial: its bytes written) */
};

#define REPLY_MAX 512 /* an FDL telegram is at most 255 bytes */

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Wait until ``until`` for the port or the wake descriptor: 0 time over (never before it),
 * 1 port readable, 2 wake readable (looked at first), -1 port error or hang-up. */
static int wait_for(int fd, int wake, double until) {
    struct pollfd p[2] = {{fd, POLLIN, 0}, {wake, POLLIN, 0}};
    nfds_t n = wake >= 0 ? 2 : 1;
    for (;;) {
        double left = until - now_s();
        if (left < 0) left = 0;
        struct timespec ts;
        ts.tv_sec = (time_t)left;
        ts.tv_nsec = (long)((left - (double)ts.tv_sec) * 1e9);
        p[0].revents = p[1].revents = 0;
        int r = ppoll(p, n, &ts, NULL);
        if (r < 0) {
            if (errno == EINTR) continue;
            return -1;
        }
        if (n == 2 && p[1].revents) return 2;
        if (p[0].revents & POLLIN) return 1;
        if (p[0].revents) return -1;
        if (now_s() >= until) return 0;
    }
}

typedef struct {
    int fd, wake;
    double deadline, tsyn, reply_wait, t_char, idle_since, busy_until, horizon, last_end;
    double gc_due, gc_period;
    int skipped; /* the last broadcast was not due: left out */
    Py_ssize_t n;
    const char **exp;
    Py_ssize_t *exp_len;
    const char **req;
    Py_ssize_t *req_len;
    /* out */
    double *times;
    Py_ssize_t ntimes;
    char rest[REPLY_MAX];
    Py_ssize_t rest_len;
    double rest_at;
    Py_ssize_t partial;
    Py_ssize_t bytes_in, bytes_out;
} Ring;

/* The reply of exchange i: 0 taken, else a STOP_* reason. An exchange expecting no reply
 * is a broadcast: nobody answers, the line is free TSYN after its end. */
static int take_reply(Ring *g, Py_ssize_t i) {
    g->rest_len = 0;
    if (g->exp_len[i] == 0) {
        if (g->skipped) { /* left out: nothing on the line */
            g->skipped = 0;
            g->times[g->ntimes++] = NAN;
            return 0;
        }
        double free_at = g->last_end + g->tsyn;
        if (free_at > g->busy_until) g->busy_until = free_at;
        g->times[g->ntimes++] = g->last_end;
        return 0;
    }
    for (;;) {
        int w = wait_for(g->fd, g->wake, g->deadline);
        if (w == 0) return STOP_TIMEOUT;
        if (w == 2) return STOP_WAKE;
        if (w < 0) return STOP_PORT;
        ssize_t got = read(g->fd, g->rest + g->rest_len, REPLY_MAX - g->rest_len);
        if (got < 0 && (errno == EAGAIN || errno == EINTR)) continue;
        if (got <= 0) return STOP_PORT;
        g->rest_len += got;
        g->bytes_in += got;
        g->rest_at = now_s();
        Py_ssize_t want = g->exp_len[i];
        if (g->rest_len < want && memcmp(g->rest, g->exp[i], (size_t)g->rest_len) == 0)
            continue; /* the start of the expected reply: the rest is on its way */
        if (g->rest_len != want || memcmp(g->rest, g->exp[i], (size_t)want) != 0)
            return STOP_DIFFER;
        g->rest_len = 0;
        g->times[g->ntimes++] = g->rest_at;
        if (g->rest_at > g->idle_since) g->idle_since = g->rest_at;
        return 0;
    }
}

/* The request of exchange i + 1, once the line was idle: 0 written, else a STOP_* reason. */
static int send_request(Ring *g, Py_ssize_t i) {
    double free_at = g->idle_since + g->tsyn;
    if (g->busy_until > free_at) free_at = g->busy_until;
    if (free_at > g->horizon) return STOP_HORIZON;
    if (free_at > now_s()) {
        int w = wait_for(g->fd, g->wake, free_at);
        if (w == 1) return STOP_BYTES;
        if (w == 2) return STOP_WAKE;
        if (w < 0) return STOP_PORT;
    }
    int broadcast = i + 1 < g->n && g->exp_len[i + 1] == 0;
    if (broadcast && now_s() < g->gc_due) { /* not due: left out, the next follows */
        g->skipped = 1;
        g->times[g->ntimes++] = NAN;
        return 0;
    }
    const char *data = g->req[i];
    Py_ssize_t len = g->req_len[i];
    ssize_t put = write(g->fd, data, (size_t)len);
    double at = now_s();
    if (broadcast) g->gc_due = at + g->gc_period;
    if (put != len) {
        g->partial = put < 0 ? 0 : put;
        g->bytes_out += g->partial;
        g->times[g->ntimes++] = at;
        return STOP_WRITE;
    }
    g->bytes_out += len;
    g->times[g->ntimes++] = at;
    double end = at + (double)len * g->t_char;
    g->last_end = end;
    if (end > g->idle_since) g->idle_since = end;
    g->deadline = end + g->reply_wait;
    return 0;
}

static int run_ring(Ring *g) {
    for (Py_ssize_t i = 0; i < g->n; i++) {
        int stop = take_reply(g, i);
        if (stop) return stop;
        if (i + 1 == g->n) return STOP_END;
        stop = send_request(g, i);
        if (stop) return stop;
    }
    return STOP_END;
}

/* The calling thread under SCHED_FIFO at ``priority``; 1 done (``was``/``param`` hold
 * what to put back), -errno refused. */
static int raise_priority(int priority, int *was, struct sched_param *param) {
    *was = sched_getscheduler(0);
    if (*was < 0 || sched_getparam(0, param) != 0) return -errno;
    struct sched_param fifo;
    memset(&fifo, 0, sizeof fifo);
    fifo.sched_priority = priority;
    if (sched_setscheduler(0, SCHED_FIFO, &fifo) != 0) return -errno;
    return 1;
}

static int bytes_items(PyObject *seq, Py_ssize_t n, const char **ptr, Py_ssize_t *len) {
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *item = PyTuple_GET_ITEM(seq, i);
        if (!PyBytes_Check(item)) {
            PyErr_SetString(PyExc_TypeError, "the ring's telegrams are bytes");
            return -1;
        }
        ptr[i] = PyBytes_AS_STRING(item);
        len[i] = PyBytes_GET_SIZE(item);
    }
    return 0;
}

static PyObject *ring_run(PyObject *self, PyObject *args) {
    (void)self;
    Ring g;
    memset(&g, 0, sizeof g);
    PyObject *expected, *requests;
    int priority;
    if (!PyArg_ParseTuple(args, "iidO!O!ddddddidd", &g.fd, &g.wake, &g.deadline, &PyTuple_Type,
                          &expected, &PyTuple_Type, &requests, &g.tsyn, &g.reply_wait,
                          &g.t_char, &g.idle_since, &g.busy_until, &g.horizon, &priority,
                          &g.gc_due, &g.gc_period))
        return NULL;
    g.n = PyTuple_GET_SIZE(expected);
    if (PyTuple_GET_SIZE(requests) + 1 != g.n || g.n < 1) {
        PyErr_SetString(PyExc_ValueError, "a ring of n exchanges: n replies, n - 1 requests");
        return NULL;
    }
    size_t n = (size_t)g.n;
    g.exp = PyMem_Calloc(n, sizeof(char *));
    g.exp_len = PyMem_Calloc(n, sizeof(Py_ssize_t));
    g.req = PyMem_Calloc(n, sizeof(char *));
    g.req_len = PyMem_Calloc(n, sizeof(Py_ssize_t));
    g.times = PyMem_Calloc(2 * n, sizeof(double));
    PyObject *out = NULL;
    if (!g.exp || !g.exp_len || !g.req || !g.req_len || !g.times) {
        PyErr_NoMemory();
        goto done;
    }
    if (bytes_items(expected, g.n, g.exp, g.exp_len) < 0 ||
        bytes_items(requests, g.n - 1, g.req, g.req_len) < 0)
        goto done;
    for (Py_ssize_t i = 0; i < g.n; i++) {
        if (g.exp_len[i] > REPLY_MAX) {
            PyErr_SetString(PyExc_ValueError, "a reply longer than a telegram");
            goto done;
        }
    }
    g.partial = -1;
    int stop, realtime = 0, was = 0;
    struct sched_param param;
    memset(&param, 0, sizeof param);
    Py_BEGIN_ALLOW_THREADS
    if (priority > 0) realtime = raise_priority(priority, &was, &param);
    stop = run_ring(&g);
    if (realtime == 1) sched_setscheduler(0, was, &param);
    Py_END_ALLOW_THREADS

    PyObject *times = PyTuple_New(g.ntimes);
    if (!times) goto done;
    for (Py_ssize_t i = 0; i < g.ntimes; i++) {
        PyObject *t = PyFloat_FromDouble(g.times[i]);
        if (!t) {
            Py_DECREF(times);
            goto done;
        }
        PyTuple_SET_ITEM(times, i, t);
    }
    out = Py_BuildValue("(iNy#ddnnni)", stop, times, g.rest, g.rest_len, g.rest_at, g.idle_since,
                        g.partial, g.bytes_in, g.bytes_out, realtime);
done:
    PyMem_Free(g.exp);
    PyMem_Free(g.exp_len);
    PyMem_Free(g.req);
    PyMem_Free(g.req_len);
    PyMem_Free(g.times);
    return out;
}

static PyMethodDef methods[] = {
    {"run", ring_run, METH_VARARGS, "Run a steady ring (see adapters/link/ring.py)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_ring", "The steady ring, compiled (adapters/link/ring.py).", -1,
    methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__ring(void) { return PyModule_Create(&module); }
